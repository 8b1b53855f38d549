"""Work-precision measurements and the ``model: auto`` choice made from them."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["auto_model", "work_precision"],
    submod_attrs={
        "auto_model": ["resolve_model"],
    },
)
