"""Studies over many runs of a scene: parameter variations, the Dask executor, Monte Carlo
runs and their report (docs/montecarlo.md)."""
