"""One sample period of the loop on a plant, without middleware: :class:`LoopStep`.

Both the one-process loop (:func:`stillframe.loop.closed_loop.run_closed_loop`) and sim_node run
their sample periods through it, so that the two give the same numbers by construction. Per
period k:

1. :meth:`LoopStep.sample`: the structure events due at sample k applied to the plant
   (:attr:`~stillframe.loop.spec.LoopSpec.events`, :attr:`LoopStep.changed`), then the plant's
   readings at t_k (the actuation of the period before still applied).
2. :meth:`LoopStep.offer`: the commands that come for it, each through its topic's
   :class:`~stillframe.loop.command_gate.CommandGate` (the writer, when the caller knows one, then
   the value and the stamp); a command taken is held until the next one.
3. :meth:`LoopStep.advance`: the command of the period (with ``actuators.delay_periods`` = d, the
   one answering sample k − d, :class:`~stillframe.plant.actuation_delay.ActuationDelay`), zero
   actuation in the safe state (the newest command ``command_timeout_periods`` old) or while the
   real-time miss-rate guard holds (:class:`~stillframe.loop.watchdog.MissRateGuard`), then the
   plant advanced over the period.

What the caller does between 1 and 3 is its own: the one-process loop calls the estimator and the
controller; sim_node publishes the readings and waits for the command (its pacing, in lock-step
or real time, and whether the command missed its deadline, which it tells :meth:`advance`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from stillframe.contract.codecs import SampleGrid
from stillframe.contract.signals import Sample
from stillframe.loop.command_gate import CommandGate
from stillframe.loop.spec import LoopSpec, StructureEvent
from stillframe.loop.watchdog import MissRateGuard, command_expired
from stillframe.loop.writer_gate import WriterGate
from stillframe.plant.actuation_delay import ActuationDelay
from stillframe.plant.protocol import Plant

__all__ = ["COUNTS", "Advanced", "LoopStep"]

#: what :attr:`LoopStep.counts` counts: commands refused by a gate, samples in the safe state,
#: samples the miss-rate guard held at zero
COUNTS = ("rejected_commands", "safe_state_samples", "degraded_samples")


@dataclass(frozen=True)
class Advanced:
    """What one period applied: ``command`` [torque, force] as the loop commanded it for the
    period (after the safe state), ``applied`` what the actuators applied (after their
    saturation and slew limits), whether its command was late in real time (``missed``), and
    whether the miss-rate guard changed its state in this period."""

    command: np.ndarray
    applied: np.ndarray
    missed: bool
    guard_changed: bool


class LoopStep:
    """The sample periods of one run on ``plant`` (module docstring).

    ``writers``: a writer gate per command topic (the node's view of the graph); None where no
    writer is told apart (the one-process loop)."""

    def __init__(self, spec: LoopSpec, plant: Plant,
                 writers: Sequence[WriterGate | None] = (None, None)) -> None:
        self.spec = spec
        self.plant = plant
        self.grid = SampleGrid(spec.period)
        self.gates = [CommandGate(bound, writer, active=i == spec.active)
                      for i, (bound, writer) in enumerate(zip(spec.bounds, writers, strict=True))]
        self.delay = ActuationDelay(spec.delay_periods)
        self.guard = MissRateGuard(spec.miss_window, spec.command_miss_limit)
        self.command = np.zeros(2)          # [torque, force] held
        self.command_ns = [-1, -1]          # their stamps (-1: none yet)
        self.k = 0                          # the period in progress (or next)
        self.now_ns = 0                     # its sample's stamp
        self.counts = dict.fromkeys(COUNTS, 0)
        #: the structure events applied at the current sample (most samples: none)
        self.changed: tuple[StructureEvent, ...] = ()
        self.applied_events: list[StructureEvent] = []

    # -- 1. the sample -----------------------------------------------------------------
    def sample(self) -> Sample:
        """Period ``k`` begins: the structure events due applied, the plant's readings at t_k."""
        self.changed = self._change_structure()
        sample = self.plant.sample()
        self.now_ns = SampleGrid.ns(sample.t)
        return sample

    def _change_structure(self) -> tuple[StructureEvent, ...]:
        """The scene's events due at sample ``k``, applied to the plant in their order."""
        events = self.spec.events[len(self.applied_events):]
        due = tuple(e for e in events if e.sample <= self.k)
        for event in due:
            self.plant.change_structure(event.index)
        self.applied_events.extend(due)
        return due

    def event_records(self) -> list[dict[str, object]]:
        """The structure events applied so far, as the result tells them."""
        return [e.record(self.spec.period) for e in self.applied_events]

    # -- 2. the commands ---------------------------------------------------------------
    def admits(self, actuator: int, gid: bytes, sequence: int = 0,
               data: bytes | memoryview = b"") -> bool:
        """Whether writer ``gid`` (or, without one, the writer that numbered the sample
        ``sequence``; with the run's token, the sample's CDR ``data`` carrying it) may command
        ``actuator``; counted as a refused command if not. Asked before the command is decoded."""
        if self.gates[actuator].admits(gid, sequence, data):
            return True
        self.counts["rejected_commands"] += 1
        return False

    def offer(self, actuator: int, value: float, stamp_ns: int) -> bool:
        """A command for ``actuator`` stamped ``stamp_ns``: taken (True) or refused by its
        gate's checks (non-finite, beyond the bound, a stamp from the future or before the one
        held) and counted."""
        gate = self.gates[actuator]
        if not gate.active:
            gate.rejected["inactive_actuator"] += 1
        elif gate.check(value, stamp_ns, self.now_ns, self.command_ns[actuator]):
            self.command[actuator], self.command_ns[actuator] = value, stamp_ns
            if actuator == self.spec.active:
                self.delay.put(self.grid.index(stamp_ns), self.command)
            return True
        self.counts["rejected_commands"] += 1
        return False

    @property
    def answered(self) -> bool:
        """Whether the command for the current sample has been taken (always, without a
        controller)."""
        active = self.spec.active
        return active is None or self.command_ns[active] == self.now_ns

    def timed_out(self) -> bool:
        """The newest command taken is ``command_timeout_periods`` periods older than the
        sample whose command is due now (or none came for as long): the safe state."""
        spec = self.spec
        return spec.active is not None and command_expired(
            self.now_ns - spec.delay_periods * spec.period_ns, self.command_ns[spec.active],
            spec.command_timeout_periods * spec.period_ns)

    # -- 3. the advance ----------------------------------------------------------------
    def advance(self, *, missed: bool = False) -> Advanced:
        """Period ``k`` ends: its command (``missed``: the caller's deadline passed without the
        command of this sample), the safe state or the guard, the plant advanced."""
        spec = self.spec
        if spec.delay_periods:
            control, late = self.delay.due(self.k)
            missed = missed or (late and not spec.lockstep)
        else:
            control = self.command.copy()
        was = self.guard.tripped
        degraded = (not spec.lockstep and spec.active is not None
                    and self.guard.record(missed))
        if self.timed_out():
            control[spec.active] = 0.0
            self.counts["safe_state_samples"] += 1
        elif degraded:
            control[spec.active] = 0.0
            self.counts["degraded_samples"] += 1
        applied = self.plant.advance(control)
        self.k += 1
        return Advanced(control, applied, missed, self.guard.tripped != was)

    def gate_reports(self, names: Sequence[str]) -> dict[str, dict[str, object]]:
        """Each command topic's gate by its name in ``names``: the writer taken, the writers
        ignored, the refusals by reason."""
        return {name: gate.report() for gate, name in zip(self.gates, names, strict=True)}
