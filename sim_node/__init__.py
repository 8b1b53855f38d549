"""The simulator: a scene-driven plant with sensor and actuator models (DESIGN.md, sim_node).

Plain numpy; the node that publishes the topic contract wraps :class:`sim_node.plant.Plant`.
"""
