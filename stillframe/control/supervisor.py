"""Around a control law: enable time, saturation and a watchdog (docs/nodes.md, watchdog).

Called once per control period with the newest estimate (or None when none arrived). Zero
command before ``start`` and while ``enabled`` is False (switched at run time); zero command
and the ``watchdog`` flag when the newest estimate is ``watchdog_periods`` periods old or more;
a non-finite law output also gives zero (flagged ``singular``); otherwise the law's command
clipped to ±:attr:`~stillframe.control.limits.CommandLimits.magnitude` (the tighter of the
controller's limit and the actuator's saturation: a command the actuator cannot apply is never
sent), or to ±:data:`~stillframe.config.loop_sections.COMMAND_BOUND` without either (a command
the simulator would refuse is never sent). A law output more than :data:`RUNAWAY_FACTOR` times
that bound is flagged ``runaway`` (counted, and ``/diagnostics`` warns): the sign of an estimate
or a design that no longer matches the plant. The controller's limit can change while it runs
(:meth:`Controller.set_limit`): the law takes the new limits at its next sample. A law that can
fall back to a safe command (MPC: a solve that did not finish) keeps its count in ``fallbacks``;
``fallback`` here follows it (``/diagnostics`` warns). A ``probe`` (``adaptation.probe_std``) is
added to the law's command before the clip: entry k at the sample k · period, the white torque
that lets the loop's own records identify the plant
(:mod:`stillframe.identification.loop_structure`).
:meth:`Controller.take_law` hands the supervisor another design's law at a sample boundary.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from stillframe.config.loop_sections import COMMAND_BOUND
from stillframe.contract.signals import Command, Estimate
from stillframe.control.limits import CommandLimits
from stillframe.control.prediction import DelayPredictor
from stillframe.durations import Durations

#: A law output beyond this multiple of the command's limit is flagged ``runaway``.
RUNAWAY_FACTOR = 10.0

Law = Callable[[np.ndarray, float], tuple[float, bool]]
"""A control law: ``law(z, force) -> (command, singular)`` on the design model's state z."""

#: no limit of the controller's nor of an actuator's
NO_LIMITS = CommandLimits()


@runtime_checkable
class LimitedLaw(Protocol):
    """A law that plans with the command's limits (the anti-windup LQG, the MPC): told when the
    controller's limit changes, it takes the new limits at its next call."""

    def __call__(self, z: np.ndarray, force: float) -> tuple[float, bool]: ...

    def set_limits(self, limits: CommandLimits) -> None:
        """Take ``limits`` at the next call (the controller's limit changed)."""


@dataclass
class ControllerCounters:
    """The controller's counts for ``/diagnostics``: commands, commands clipped to the limit,
    singular ones (the law said so, or its output was not finite), watchdog zeros, runaway outputs
    (singular, or beyond :data:`RUNAWAY_FACTOR` times the limit) and the law's fallbacks (the MPC's
    anti-windup LQG)."""

    commands: int = 0
    saturated: int = 0
    singular: int = 0
    watchdog: int = 0
    runaway: int = 0
    fallback: int = 0


class Controller:
    """A law acting on one actuator (0: pendulum torque, 1: floor-3 force)."""

    def __init__(self, law: Law, *, actuator: int, period: float,
                 limits: CommandLimits = NO_LIMITS, start: float = 0.0,
                 watchdog_periods: int = 3, predictor: DelayPredictor | None = None,
                 probe: np.ndarray | None = None) -> None:
        self.law = law
        self.probe = probe
        self.predictor = predictor
        self.actuator = actuator
        self.period = period
        self.start = start
        self.limits = limits
        self.watchdog_periods = watchdog_periods
        self.enabled = True
        self.latest: Estimate | None = None
        self.counters = ControllerCounters()
        self.law_s = Durations()           # wall time of each law evaluation (compute_stats)
        self.law_cpu_s = Durations()       # … and this thread's CPU time for it

    @property
    def limit(self) -> float | None:
        """The controller's own limit (None: none), besides the actuator's saturation."""
        return self.limits.limit

    def set_limit(self, limit: float | None) -> None:
        """A new controller limit (None or 0: none), for the supervisor's clip and for a law
        that plans with the limits (:class:`LimitedLaw`) from the next sample on."""
        self.limits = self.limits.with_limit(limit)
        if isinstance(self.law, LimitedLaw):
            self.law.set_limits(self.limits)

    def take_law(self, other: Controller) -> None:
        """From the next command on, the law (and the delay predictor) of ``other``, a controller
        of another design for this actuator; this supervisor's limits, enable state, watchdog,
        probe and counters stay."""
        self.law, self.predictor = other.law, other.predictor
        if isinstance(self.law, LimitedLaw):
            self.law.set_limits(self.limits)

    def compute_stats(self) -> dict[str, float]:
        """p50, p99 and max of the law's wall time per sample [s], ``cpu_…`` of its CPU time
        (what preemption by other processes does not inflate), ``solve_…`` of the solver's own
        wall time for a law that keeps it (MPC); empty before the first command."""
        stats: dict[str, float] = {}
        for name, times in (("", self.law_s), ("cpu_", self.law_cpu_s),
                            ("solve_", getattr(self.law, "solve_s", None))):
            if times is not None and times.count:
                stats.update({f"{name}{key}": 1e-3 * ms for key, ms in times.summary().items()})
        return stats

    def stale(self, t: float) -> bool:
        """True when at time t the newest estimate is ``watchdog_periods`` periods old or more
        (or there is none): the watchdog's condition."""
        return (self.latest is None or t - self.latest.t
                >= self.watchdog_periods * self.period - 1e-9 * self.period)

    def command(self, t: float, estimate: Estimate | None, force: float) -> Command:
        """The command at time t from the newest estimate and the measured excitation force
        (with a ``predictor``, from the state predicted to when the command takes effect)."""
        out = self._command(t, estimate, force)
        if self.predictor is not None:
            self.predictor.sent(out.t, float(out.vector[self.actuator]))
        return out

    def _command(self, t: float, estimate: Estimate | None, force: float) -> Command:
        c = self.counters
        c.commands += 1
        if estimate is not None and (self.latest is None or estimate.t > self.latest.t):
            self.latest = estimate
        latest = self.latest
        tolerance = 1e-9 * self.period
        if self.stale(t):
            c.watchdog += 1
            return Command(t, watchdog=True)
        out = Command(latest.t)
        if t < self.start - tolerance or not self.enabled:
            return out
        out.enabled = True
        z = latest.z if self.predictor is None else self.predictor.ahead(
            latest.t, latest.z,
            None if latest.applied is None else float(latest.applied[self.actuator]))
        started, started_cpu = time.perf_counter(), time.thread_time()
        value, singular = self.law(z, force)
        value, out.singular = float(value), bool(singular)
        if self.probe is not None:
            k = round(t / self.period)
            value += float(self.probe[k]) if k < self.probe.size else 0.0
        self.law_s.add(time.perf_counter() - started)
        self.law_cpu_s.add(time.thread_time() - started_cpu)
        c.fallback = getattr(self.law, "fallbacks", 0)   # laws with a safe fallback count it
        if not np.isfinite(value):
            value, out.singular = 0.0, True
        bound = self.limits.magnitude or COMMAND_BOUND
        out.runaway = out.singular or bool(abs(value) > RUNAWAY_FACTOR * bound)
        if abs(value) > bound:
            value, out.saturated = float(np.clip(value, -bound, bound)), True
        c.saturated += out.saturated
        c.runaway += out.runaway
        c.singular += out.singular
        if self.actuator == 0:
            out.torque = value
        else:
            out.force = value
        return out
