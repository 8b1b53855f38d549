"""The simulator: a scene-driven plant with sensor and actuator models (docs/nodes.md).

Plain numpy; the node that publishes the topic contract wraps
:class:`stillframe.plant.frame_plant.FramePlant`.
"""
