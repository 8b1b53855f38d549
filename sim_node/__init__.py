"""The simulator: a scene-driven plant with sensor and actuator models (docs/nodes.md).

Plain numpy; the node that publishes the topic contract wraps
:class:`stillframe.plant.frame_plant.FramePlant`.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["node"],
    submod_attrs={
        "node": ["SimNode", "main"],
    },
)
