"""Control laws for the loop: LQG, extended Udwadia–Kalaba and passivity-based control behind a
supervisor (what controller_node runs)."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["euk", "factory", "limits", "lqg", "mpc", "passivity", "prediction", "supervisor"],
    submod_attrs={
        "factory": ["make_controller"],
        "supervisor": ["Controller"],
        "limits": ["CommandLimits"],
        "lqg": ["design_lqr"],
    },
)
