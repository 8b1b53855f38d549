"""The estimator and the controller composed in one process (``stillframe launch --compose``)."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["node"],
    submod_attrs={
        "node": ["Container", "main"],
    },
)
