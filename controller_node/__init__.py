"""Control laws for the loop: LQG (DLQR on a linear design model) and the extended
Udwadia–Kalaba controller in its two actuator variants, behind a supervisor that adds the enable
time, saturation and a watchdog (docs/nodes.md).

Plain numpy; the node wraps :func:`stillframe.control.factory.make_controller`'s ``command``.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["node"],
    submod_attrs={
        "node": ["ControllerNode", "main"],
    },
)
