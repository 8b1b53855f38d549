"""State estimation for the loop: steady-state and time-varying Kalman filters on a linear model,
an EKF on the nonlinear model, and the exact-state pass-through (docs/nodes.md).

Plain numpy; the node wraps :func:`stillframe.estimation.factory.make_estimator`'s ``step``.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["node"],
    submod_attrs={
        "node": ["EstimatorNode", "main"],
    },
)
