"""The scene's estimator: ``estimator.type`` on the design model (scene ``design`` section)."""

from __future__ import annotations

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract.signals import Estimate, Sample
from stillframe.design.coordinates import to_design
from stillframe.dynamics.models import FrameModel
from stillframe.errors import InputError
from stillframe.estimation.base import Counters, Filter
from stillframe.estimation.ekf import ExtendedKalman
from stillframe.estimation.kalman import SteadyStateKalman, TimeVaryingKalman

__all__ = ["FILTERS", "Estimator", "TruthEstimator", "initial_physical", "make_estimator"]

FILTERS = {"kf": SteadyStateKalman, "tvkf": TimeVaryingKalman, "ekf": ExtendedKalman}


class TruthEstimator:
    """Full-state feedback: the simulator's true state (the thesis's EUK runs without EKF)."""

    def __init__(self, model: FrameModel) -> None:
        self.model = model
        self.t: float | None = None
        self.counters = Counters()

    def step(self, sample: Sample, control: np.ndarray) -> Estimate | None:
        """The simulator's true state of ``sample`` as the estimate (its design coordinates beside
        it, no covariance); None, counted stale, for a sample without truth or not newer than the
        last."""
        if sample.truth is None or (self.t is not None and not sample.t > self.t):
            self.counters.stale += 1
            return None
        self.t = sample.t
        self.counters.updates += 1
        return Estimate(sample.t, to_design(self.model, sample.truth), sample.truth.copy(),
                        applied=np.asarray(control, dtype=float))


def initial_physical(scene: Scene) -> np.ndarray:
    """The scene's initial [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇]."""
    i = scene.initial
    return np.array([*i.floors, i.phi, *i.floor_velocities, i.phi_rate], dtype=float)


#: what estimates the state: the simulator's truth, or a filter
Estimator = TruthEstimator | Filter


def make_estimator(scene: Scene, design: FrameModel) -> Estimator:
    """The estimator of ``scene.estimator.type`` (not ``none``)."""
    kind = scene.estimator.type
    if kind == "truth":
        return TruthEstimator(design)
    if kind not in FILTERS:
        raise InputError(f"estimator.type: {kind!r} gives no state estimate")
    return FILTERS[kind](design, scene.estimator, scene.excitation.floor, initial_physical(scene),
                         1.0 / scene.sensors.rate_hz)
