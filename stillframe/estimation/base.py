"""What every estimator does per sample: reject stale samples and non-finite channels (and count
them), predict from the previous sample time, update with the channels that arrived (a partial
update when some are missing), and report the estimate."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from stillframe.config.loop_sections import Estimator
from stillframe.contract.signals import Estimate, Sample
from stillframe.design.coordinates import design_map, physical_selector
from stillframe.dynamics.models import FrameModel
from stillframe.errors import IntegrationError, StillframeError

__all__ = ["Counters", "Filter", "FilterState"]


@dataclass
class Counters:
    """For ``/diagnostics``: samples used, rejected (stale, non-finite), channels missing."""

    updates: int = 0
    stale: int = 0
    non_finite: int = 0
    missing: int = 0

    @property
    def rejected(self) -> int:
        """Samples refused: stale ones and those with non-finite readings."""
        return self.stale + self.non_finite


@dataclass(frozen=True)
class FilterState:
    """What a filter's steps change, taken between two samples (:meth:`Filter.state`) to go back
    to (:meth:`Filter.restore`): a late reading re-runs the samples after it from here."""

    x: np.ndarray
    P: np.ndarray
    t: float | None
    force: float
    counters: Counters
    extra: Any = None
    """What a subclass keeps besides (:meth:`Filter._extra_state`)."""


class Filter(ABC):
    """A recursive estimator on a design :class:`FrameModel`; state z = [q, q̇]."""

    def __init__(self, model: FrameModel, config: Estimator, excited_floor: int,
                 initial_physical: np.ndarray) -> None:
        self.model = model
        self.excited_floor = excited_floor
        self.S = physical_selector(model)
        self.T = T = design_map(model)
        self.Q, self.R = self.noise_covariances(config.process_noise_std,
                                                config.measurement_noise_std)
        self.x = T @ (np.asarray(initial_physical) + np.asarray(config.initial_offset))
        self.P = T @ np.diag(np.square(config.initial_std)) @ T.T
        self.t: float | None = None
        self.force = 0.0
        self.counters = Counters()
        self._covariance: tuple[np.ndarray | None, np.ndarray | None] = (None, None)

    def noise_covariances(self, process_std: Sequence[float],
                          measurement_std: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """Q (per sample, physical stds mapped to the design state) and R (eq. 5.221–5.222)."""
        return (self.T @ np.diag(np.square(process_std)) @ self.T.T,
                np.diag(np.square(measurement_std)))

    def set_noise(self, process_std: list[float], measurement_std: list[float]) -> None:
        """New noise settings at run time; what depends on them is recomputed (InputError, and
        nothing changed, if the filter cannot be designed with them)."""
        self.Q, self.R = self.noise_covariances(process_std, measurement_std)

    def continue_from(self, previous: Filter) -> None:
        """Go on from ``previous``, a filter of the same run on another design model (a
        hand-over at a sample boundary): its physical estimate mapped into this design's state
        (inner DOFs in static equilibrium), its time, its last force and its counters; the
        covariance stays this filter's own (the stationary one, or the initial one)."""
        self.x = self.T @ (previous.S @ previous.x)
        self.t, self.force, self.counters = previous.t, previous.force, previous.counters

    def state(self) -> FilterState:
        """The filter as it stands, to :meth:`restore` later."""
        return FilterState(self.x.copy(), self.P.copy(), self.t, self.force,
                           replace(self.counters), self._extra_state())

    def restore(self, state: FilterState) -> None:
        """Go back to ``state`` (taken from this filter by :meth:`state`): the samples after it
        are then stepped again."""
        self.x, self.P, self.t, self.force = state.x.copy(), state.P.copy(), state.t, state.force
        self.counters = replace(state.counters)
        self._restore_extra(state.extra)

    def _extra_state(self) -> Any:
        """What a subclass's steps change besides x, P, t and the force (none here)."""
        return None

    def _restore_extra(self, extra: Any) -> None:
        """Take back what :meth:`_extra_state` gave, after x and P were restored (nothing
        here)."""
        return None

    def step(self, sample: Sample, control: np.ndarray) -> Estimate | None:
        """Use one sample; ``control`` = [torque, force] applied since the previous sample (the
        estimate's ``applied``).

        Returns None (and counts it) for a sample not newer than the last one used; raises
        :class:`~stillframe.errors.IntegrationError` when the estimate leaves the finite range
        (:meth:`diverged`).
        """
        c = self.counters
        if self.t is not None and not sample.t > self.t:
            c.stale += 1
            return None
        arrived = np.asarray(sample.present, dtype=bool)
        finite = np.isfinite(sample.measurements)
        present = arrived[:4] & finite
        if not arrived.all():
            c.missing += int(np.count_nonzero(~arrived))
        if not finite.all():
            c.non_finite += int(np.count_nonzero(arrived[:4] & ~finite))
        force = self.force
        if sample.present[4]:
            if np.isfinite(sample.force):
                force = float(sample.force)
            else:
                c.non_finite += 1
        control = np.asarray(control, dtype=float)
        try:   # a diverging estimate is checked below, not warned about on the way
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                if self.t is not None:
                    self.predict(sample.t - self.t, self.force, force, control)
                if present.any():
                    self.update(np.asarray(sample.measurements, dtype=float), present, force,
                                control)
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            if isinstance(exc, StillframeError):
                raise
            raise self.diverged(sample.t) from None
        if not (np.isfinite(self.x).all() and np.isfinite(self.P).all()):
            raise self.diverged(sample.t)
        self.t, self.force = sample.t, force
        c.updates += 1
        estimate = self.estimate()
        estimate.applied = control
        return estimate

    def diverged(self, t: float) -> IntegrationError:
        """The error of an estimate that left the finite range at ``t`` (the filter's model and
        noise settings no longer follow the plant): the run cannot go on."""
        return IntegrationError(
            f"estimator.type: the {type(self).__name__} estimate left the finite range at "
            f"t = {t:.6g} s (its design model and noise settings do not follow this plant)")

    def estimate(self) -> Estimate:
        """The current :class:`~stillframe.contract.signals.Estimate`: the time, the design state z,
        the physical state S z and its covariance S P Sᵀ (formed again only when P changed,
        read-only)."""
        if self.P is not self._covariance[0]:  # a stationary filter keeps P: computed once
            covariance = self.S @ self.P @ self.S.T
            covariance.flags.writeable = False
            self._covariance = (self.P, covariance)
        return Estimate(self.t, self.x.copy(), self.S @ self.x, self._covariance[1])

    @abstractmethod
    def predict(self, dt: float, force0: float, force1: float, control: np.ndarray) -> None:
        """Time update over dt, the excitation linear from force0 to force1, control held."""

    @abstractmethod
    def update(self, y: np.ndarray, present: np.ndarray, force: float,
               control: np.ndarray) -> None:
        """Measurement update with the rows ``present`` of y = [a1, a2, a3, φ]."""
