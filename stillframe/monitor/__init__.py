"""Live monitoring: the Foxglove bridge, its client and the built-in dashboard."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["dashboard", "foxglove_bridge", "foxglove_client"],
    submod_attrs={
        "dashboard": ["Dashboard"],
        "foxglove_bridge": ["FoxgloveBridge"],
    },
)
