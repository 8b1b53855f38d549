"""The design model shared by estimation and control: coordinates, discretization at the
sample period, and the discrete algebraic Riccati equation."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["coordinates", "discrete", "identified", "riccati"],
    submod_attrs={
        "coordinates": ["design_map"],
        "discrete": ["Discrete", "first_order_hold"],
        "riccati": ["solve_dare"],
        "identified": ["frame_for"],
    },
)
