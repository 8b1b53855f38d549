"""Studies over many runs of a scene: parameter variations, the Dask executor, Monte Carlo
runs and their report (docs/montecarlo.md)."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["cluster", "executor", "montecarlo", "report", "vary"],
    submod_attrs={
        "montecarlo": ["Study", "plan", "run_one"],
        "vary": ["parse_vary"],
    },
)
