"""What one run of the loop is, derived once from the validated scene: :class:`LoopSpec`.

Every process of the loop and the one-process loop read these facts here rather than derive them
again: the sample period and the integrator steps in it
(:func:`stillframe.config.scene.sample_grid`), the number of samples, the actuator the controller
drives, the bound of each command the simulator takes
(:attr:`stillframe.config.loop_sections.Actuators.bounds`), the actuation delay, and when the
simulator falls back to zero actuation (the safe state) or ends a lock-step run, and the sample
at which each of the scene's structure events applies (:class:`StructureEvent`).

The defaults of the simulator's parameters that set these (``command_timeout_periods``,
``command_miss_limit``, ``lockstep_timeout_s``) are the constants of this module; the node
declarations (:mod:`stillframe.node_runtime.declarations`) take them from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from stillframe.config.events import first_sample_at
from stillframe.config.scene import Scene, event_changes, sample_grid
from stillframe.contract.signals import actuator_of
from stillframe.errors import InputError

__all__ = [
    "COMMAND_MISS_LIMIT",
    "COMMAND_TIMEOUT_PERIODS",
    "LOCKSTEP_TIMEOUT_S",
    "MODES",
    "LoopSpec",
    "StructureEvent",
]

#: the modes of the loop, one constant for every process (launch, nodes, benchmarks)
MODES = ("lockstep", "realtime")

#: periods after which the newest command taken is too old to apply: zero actuation (the safe
#: state) until a fresh one comes
COMMAND_TIMEOUT_PERIODS = 3

#: real time: zero actuation while more than this share of the last second's samples missed
#: their command (0: never)
COMMAND_MISS_LIMIT = 0.25

#: lock-step: the longest wall time [s] one sample waits for its command while the loop's peers
#: are on the graph; past it the run ends, incomplete. Long: a lock-step run never advances
#: without the command of the current sample, so this is a guard against a peer that is alive
#: but no longer answers, not a pace.
LOCKSTEP_TIMEOUT_S = 60.0


@dataclass(frozen=True, kw_only=True)
class StructureEvent:
    """The scene's event ``index`` (:mod:`stillframe.config.events`) as the loop applies it:
    at the start of sample ``sample``, the first at or after its ``time_s``."""

    index: int
    time_s: float
    sample: int
    changes: dict[str, Any]
    """Each scene key it changes with its value after it
    (:func:`~stillframe.config.scene.event_changes`)."""

    def record(self, period: float) -> dict[str, Any]:
        """The event as the run's result and the ``structure_events`` topic tell it."""
        return {"event": self.index, "time_s": self.time_s, "applied_s": self.sample * period,
                "sample": self.sample, "changes": self.changes}


@dataclass(frozen=True, kw_only=True)
class LoopSpec:
    """One run of the loop (module docstring). Build it with :meth:`of`."""

    period: float
    """The sample period 1/``sensors.rate_hz`` [s]."""
    period_ns: int
    steps_per_sample: int
    """Integrator steps in one sample period."""
    samples: int
    """Sample periods in the run (``duration`` / period)."""
    active: int | None
    """The index in [torque, floor-3 force] the controller drives (None: no controller)."""
    bounds: tuple[float, float]
    """The bound of each command the simulator takes
    (:attr:`stillframe.config.loop_sections.Actuators.bounds`)."""
    delay_periods: int
    """``actuators.delay_periods``: the command answering sample k is applied over period k + d."""
    lockstep: bool
    lockstep_timeout_s: float
    """Lock-step: the longest wait for one sample's command (:data:`LOCKSTEP_TIMEOUT_S`)."""
    command_timeout_periods: int
    """Zero actuation once the newest command is this many periods old."""
    command_miss_limit: float
    """Real time: the miss-rate guard's limit (0: off)."""
    miss_window: int
    """Real time: the samples the miss-rate guard looks back over (one second, at least 10)."""
    events: tuple[StructureEvent, ...] = ()
    """The scene's structure events, in order, with the sample each applies at."""

    @classmethod
    def of(cls, scene: Scene, *, mode: str = "lockstep",
           lockstep_timeout_s: float = LOCKSTEP_TIMEOUT_S,
           command_timeout_periods: int = COMMAND_TIMEOUT_PERIODS,
           command_miss_limit: float = COMMAND_MISS_LIMIT) -> LoopSpec:
        """The spec of ``scene`` run in ``mode``; InputError naming what cannot run."""
        if mode not in MODES:
            raise InputError(f"mode: {mode!r}; expected one of {', '.join(MODES)}")
        period, steps = sample_grid(scene)
        if not (math.isfinite(lockstep_timeout_s) and lockstep_timeout_s > 0):
            raise InputError(f"lockstep_timeout_s: {lockstep_timeout_s!r}; expected > 0")
        return cls(period=period, period_ns=round(period * 1e9), steps_per_sample=steps,
                   samples=round(scene.duration / period), active=actuator_of(scene),
                   bounds=scene.actuators.bounds, delay_periods=scene.actuators.delay_periods,
                   lockstep=mode == "lockstep", lockstep_timeout_s=lockstep_timeout_s,
                   command_timeout_periods=command_timeout_periods,
                   command_miss_limit=command_miss_limit,
                   miss_window=max(10, round(1.0 / period)),
                   events=tuple(StructureEvent(index=i, time_s=e.time,
                                               sample=first_sample_at(e.time, period),
                                               changes=event_changes(scene, i))
                                for i, e in enumerate(scene.events)))
