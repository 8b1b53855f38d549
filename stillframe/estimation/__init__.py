"""State estimation for the loop: Kalman filters, the EKF and the exact-state pass-through
(what estimator_node runs)."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["base", "ekf", "factory", "kalman"],
    submod_attrs={
        "base": ["Filter"],
        "factory": ["make_estimator"],
    },
)
