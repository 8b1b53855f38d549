"""Monte Carlo runs of a scene: what one run does and how run i gets its values
(docs/montecarlo.md).

Run i of a study with seed S draws from ``SeedSequence(S, spawn_key=(i,))``: its first child
draws the ``--vary`` values, its second the noise seeds (``plant.seed``, ``sensors.seed``,
``excitation.seed``, unless a ``--vary`` or ``--set`` fixes them). A run depends only on the
scene, the variations, S and i, so ``--only i`` reproduces it alone and any worker may run it.

One run (:func:`run_one`, executed on a Dask worker) is
- ``closed-loop``: :func:`stillframe.loop.closed_loop.run_closed_loop` and its evaluation;
- ``simulate``: :func:`stillframe.dynamics.simulation.simulate` and its summary;
- ``identify``: a simulation under the scene's white-noise force, sampled at
  ``sensors.rate_hz`` with accelerometer noise, identified by OKID + ERA/DC of order twice the
  model's modes below 0.8 Nyquist, and scored against those modes by
  :func:`stillframe.identification.sweep.score` (worst frequency and damping error; inf: a mode
  missed).
A run whose integration diverges (:class:`~stillframe.errors.IntegrationError`) or whose
closed-loop or simulation figures are not finite counts as unstable; any other error as failed.
Both are kept in the table with their error.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stillframe.config.scene import sample_grid, scene_from_dict
from stillframe.config.schema import Section, set_dotted, show
from stillframe.errors import InputError
from stillframe.loop.parts import check_loop
from stillframe.studies.executor import Outcome
from stillframe.studies.vary import (
    Variation,
    as_overrides,
    check_nominal,
    combinations,
    draw,
    lookup,
)

__all__ = ["RunSpec", "Study", "flatten", "is_timing", "plan", "row", "run_one"]

WHATS: tuple[str, ...] = ("closed-loop", "simulate", "identify")
NOISE_SEEDS: tuple[str, ...] = ("plant.seed", "sensors.seed", "excitation.seed")
TIMING: tuple[str, ...] = ("wall_s", "loop_s", "loop_cpu_s", "steps_per_s", "cpu_s",
                           "controller_compute_s")


def is_timing(column: str) -> bool:
    """A column measured on the clock (it differs from run to run of the same values): one of
    :data:`TIMING` or a part of one (``controller_compute_s.p50``)."""
    return column.split(".", 1)[0] in TIMING
"""Figures that measure the machine, not the run (left out of comparisons)."""


@dataclass(frozen=True)
class RunSpec:
    """Run ``run``: the varied values and every override it applies to the base scene."""

    run: int
    values: dict[str, Any]
    overrides: tuple[str, ...]


@dataclass
class Study:
    """A base scene (validated, ``--set`` applied), its variations, seed and kind of run."""

    scene: dict[str, Any]
    variations: list[Variation]
    seed: int
    what: str
    fixed: set[str] = field(default_factory=set)

    @property
    def combinations(self) -> int:
        return len(combinations(self.variations))

    def spec(self, run: int) -> RunSpec:
        """Run ``run``'s values and overrides (module docstring)."""
        vary_seq, noise_seq = np.random.SeedSequence(self.seed, spawn_key=(run,)).spawn(2)
        nominals = {v.key: lookup(self.scene, v.key) for v in self.variations}
        values = draw(self.variations, nominals, run, np.random.default_rng(vary_seq))
        noise = noise_seq.generate_state(len(NOISE_SEEDS))
        seeds = {k: int(s) for k, s in zip(NOISE_SEEDS, noise, strict=True)
                 if k not in values and k not in self.fixed}
        return RunSpec(run, values, tuple(as_overrides({**seeds, **values})))

    def task(self, run: int) -> tuple[dict[str, Any], tuple[str, ...], str]:
        return self.scene, self.spec(run).overrides, self.what


def plan(scene: Section, set_overrides: list[str], variations: list[Variation], seed: int,
         what: str) -> Study:
    """Check the study before any run: known keys, numeric nominals for relative spreads, and
    for ``closed-loop`` every part the loop builds from the nominal scene and from each listed
    value (:func:`stillframe.loop.parts.check_loop`, what ``launch`` checks before a process)."""
    if what not in WHATS:
        raise InputError(f"--what {what}: one of {', '.join(WHATS)}")
    if seed < 0:
        raise InputError(f"--seed {seed}: must be a whole number >= 0")
    if what == "closed-loop" and scene.controller.type == "none":
        raise InputError("controller.type: the scene has no controller; use --what simulate")
    keys = [v.key for v in variations]
    if len(set(keys)) != len(keys):
        raise InputError(f"--vary: a key is varied twice ({', '.join(keys)})")
    loop = what == "closed-loop"
    if loop:
        check_loop(scene)
    data = scene.to_dict()
    for v in variations:
        check_nominal(v, lookup(data, v.key))
        for value in v.values:      # every listed value must make a valid scene, before a run
            trial = copy.deepcopy(data)
            set_dotted(trial, v.key, value)
            try:
                varied = scene_from_dict(trial)
                if loop:
                    check_loop(varied)
            except InputError as exc:
                raise InputError(f"--vary {v.key}: the value {show(value)}: {exc}") from None
    fixed = {item.partition("=")[0].strip() for item in set_overrides}
    return Study(data, variations, seed, what, fixed)


def flatten(value: Any, prefix: str = "") -> dict[str, Any]:
    """Nested dicts and lists as one level: ``a.b`` and 1-based ``a.b.1`` (floor 1)."""
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        for k, v in value.items():
            out |= flatten(v, f"{prefix}.{k}" if prefix else str(k))
        return out
    if isinstance(value, list | tuple):
        out = {}
        for i, v in enumerate(value, 1):
            out |= flatten(v, f"{prefix}.{i}")
        return out
    return {prefix: value}


def _closed_loop(scene: Section) -> dict[str, Any]:
    from stillframe.loop.closed_loop import run_closed_loop

    return run_closed_loop(scene).evaluation


def _simulate(scene: Section) -> dict[str, Any]:
    from stillframe.dynamics.simulation import simulate

    return simulate(scene).summary()


def _identify(scene: Section) -> dict[str, Any]:
    from stillframe.dynamics.modal_analysis import modal_table
    from stillframe.dynamics.models import build_model
    from stillframe.dynamics.simulation import simulate
    from stillframe.identification.pipeline import identify
    from stillframe.identification.sweep import score

    exc, sensors = scene.excitation, scene.sensors
    if exc.type != "white_noise" or exc.rate_hz != sensors.rate_hz:
        raise InputError("excitation: --what identify needs type white_noise with rate_hz equal "
                         "to sensors.rate_hz (a force held over each sample)")
    every = sample_grid(scene)[1]
    history = simulate(scene)
    u = history.excitation[::every, None]
    y = history.floor_accelerations[::every]
    rng = np.random.default_rng(sensors.seed)
    y = y + rng.normal(0.0, sensors.accelerometer_noise_std, y.shape)
    modes = modal_table(build_model(scene))
    f_true = np.asarray(modes["frequencies_hz"])
    z_true = np.asarray(modes["damping_ratios"])
    inside = (f_true > 0) & (f_true < 0.8 * sensors.rate_hz / 2)
    found = identify(u, y, 1.0 / sensors.rate_hz, order=2 * int(inside.sum()))
    f_id = np.asarray(found.modes.frequency_hz)
    z_id = np.asarray(found.modes.damping_ratio)
    result = score(f_id, z_id, f_true[inside], z_true[inside])
    return {**result, "order": found.order, "modes_scored": int(inside.sum()),
            "warnings": len(found.warnings)}


RUNNERS = {"closed-loop": _closed_loop, "simulate": _simulate, "identify": _identify}


def run_one(task: tuple[dict[str, Any], tuple[str, ...], str]) -> dict[str, Any]:
    """One run on a worker: the scene with its overrides, then its figures (flattened)."""
    data, overrides, what = task
    started = time.process_time()
    scene = scene_from_dict(copy.deepcopy(data), list(overrides))
    figures = flatten(RUNNERS[what](scene))
    figures["cpu_s"] = time.process_time() - started
    bad = [k for k, v in figures.items() if isinstance(v, float) and not math.isfinite(v)]
    if bad and what != "identify":  # there inf means a missed mode (score)
        figures["non_finite"] = ",".join(bad)
    return figures


def row(spec: RunSpec, outcome: Outcome) -> dict[str, Any]:
    """The table row of one run: id, status, error, varied values, figures."""
    if outcome.error is None:
        status = "unstable" if "non_finite" in outcome.value else "ok"
    else:
        status = "unstable" if outcome.error_type == "IntegrationError" else "failed"
    head = {"run": spec.run, "status": status, "error": outcome.error or ""}
    return head | flatten(spec.values) | (outcome.value or {})
