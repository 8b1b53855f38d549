"""The sample of one stamp, assembled from the topics that carry it (estimator_node; docs/nodes.md,
lock-step protocol, step 3). No clock is read here: the caller passes ``now_ns`` (monotonic
nanoseconds in the node, any integer in a test).

A stamp is used, oldest first, when it is complete (every input arrived, and in lock-step the
command answering the previous stamp too), when each input it lacks has brought a newer stamp, or
``wait_ns`` after its first message; anything but complete is a partial update and counted. A
topic's messages arrive in the order they were written (one writer, DDS), but topics are not
ordered among themselves: a newer stamp on one topic says nothing of an older one still on its way
on another, while a newer stamp on the input's own topic says its message for the older stamp is
lost. Negative stamps are
rejected and counted (``negative_stamps``).

A stamp at or before the last stamp used (``stale_messages``), or more than :data:`JUMP_NS`
after it (``future_stamps``), is counted and not taken at its word: it is held apart (at most
:data:`HELD_STAMPS` such stamps) until every input of that stamp has arrived. A stray writer's
far-future or zero stamp on one topic never gets there and is dropped; a simulator restarted at
t = 0 (or resumed after a long loss) does, and the assembly starts again at that stamp as if new
(``time_jumps``; :meth:`SampleAssembly.take_jump` tells the caller to start its filter again).

In real time an input may come after its stamp was used without it (a link's jitter, a loaded
host). Within ``revisable`` stamps of the last one used, it is not dropped: it fills in that
stamp (``late_inputs``), and :meth:`SampleAssembly.take_revision` hands the caller the stamps so
revised, to step its filter again from the oldest (the estimator's ``refilter_periods``; the
lagged-data smoothing of robot_localization does the same). Older or repeated ones are stale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stillframe.contract import topics
from stillframe.contract.codecs import ENCODER_CHANNEL, SENSOR_TOPICS, SampleGrid
from stillframe.contract.signals import Sample
from stillframe.control.prediction import CommandLog

#: How far [ns] a stamp may lie from the last stamp used before it needs every input to agree.
JUMP_NS = 1_000_000_000
#: Far-off stamps held at most (the oldest is dropped first).
HELD_STAMPS = 8
#: a reported actuation equals the command when within these (np.isclose's test)
RTOL, ATOL = 1e-9, 1e-12


_NO_VALUES = np.full(len(SENSOR_TOPICS), np.nan)
_NONE_PRESENT = np.zeros(len(SENSOR_TOPICS), dtype=bool)
_NO_ACTUATION = np.full(2, np.nan)
#: the inputs beyond the sensor channels, as indices into :attr:`SampleAssembly.newest`
_TRUTH, _FORCE = len(SENSOR_TOPICS), len(SENSOR_TOPICS) + 1


class Pending:
    """The inputs of one stamp received so far."""

    def __init__(self, ns: int, first_ns: int) -> None:
        self.ns = ns
        self.first_ns = first_ns        # when its first message arrived
        self.values = _NO_VALUES.copy()     # copies of templates: cheaper than np.full
        self.present = _NONE_PRESENT.copy()
        self.truth: np.ndarray | None = None
        self.applied = _NO_ACTUATION.copy()  # [torque, force] applied over the previous period


@dataclass
class Ready:
    """A stamp to estimate: its sample, the actuation in effect over the period before it
    ([torque, force]) and whether every input arrived."""

    ns: int
    sample: Sample
    control: np.ndarray
    complete: bool
    first_ns: int = 0
    """When the stamp's first message arrived (the caller's ``now_ns``)."""


class SampleAssembly:
    """Readings of ``inputs`` (:func:`stillframe.loop.wiring.estimator_inputs`) gathered by stamp.

    ``active`` is the actuator the controller drives (None: none); the other is taken as zero.
    ``grid`` maps the stamps back to the exact sample times.
    """

    def __init__(self, inputs: tuple[topics.TopicSpec, ...], active: int | None,
                 grid: SampleGrid, wait_ns: int | None, lockstep: bool,
                 delay_periods: int = 0, *, revisable: int = 0) -> None:
        self.needs_truth = topics.STATE_TRUTH in inputs
        self.needs_force = topics.FLOOR3_LOAD_CELL in inputs
        self.active = active
        self.grid = grid
        self.wait_ns = wait_ns
        self.lockstep = lockstep
        self.pending: dict[int, Pending] = {}
        self.held: dict[int, Pending] = {}      # far-off stamps, until one is complete
        self.jumped = False
        self.last_ns = -1               # the last stamp used
        #: per input (the sensor channels, then truth and the applied force), the newest stamp
        #: that arrived on its topic
        self.newest = np.full(_FORCE + 1, -1, dtype=np.int64)
        self.command_ns = [-1, -1]      # the newest command's stamp, per actuator
        #: per actuator, the commands received by the sample they answer
        self.commands = [CommandLog(), CommandLog()]
        #: the command in effect over the period before sample k answers k − 1 − d
        self.answer_lag = 1 + delay_periods
        #: the newest actuation the simulator reported it applied, [torque, force], and
        #: whether it was the command in effect then (the simulator applying the commands)
        self.last_applied = np.zeros(2)
        self.applying = np.ones(2, dtype=bool)
        #: how many stamps back a late input still revises its stamp (0: never)
        self.revisable = revisable
        #: the partial stamps used within ``revisable`` of the last one, as used
        self.recent: dict[int, tuple[Pending, Ready]] = {}
        self.revised: set[int] = set()
        self.counts = {"stale_messages": 0, "partial_updates": 0, "rejected_commands": 0,
                       "command_waits_timed_out": 0, "applied_reported": 0,
                       "negative_stamps": 0, "future_stamps": 0, "time_jumps": 0,
                       "late_inputs": 0}

    # -- inputs --------------------------------------------------------------------------
    def _slot(self, ns: int, now_ns: int) -> Pending | None:
        if ns < 0:
            self.counts["negative_stamps"] += 1
            return None
        if ns in self.recent:
            return self.recent[ns][0]
        far_ahead = self.last_ns >= 0 and ns > self.last_ns + JUMP_NS
        if far_ahead or ns <= self.last_ns:
            self.counts["future_stamps" if far_ahead else "stale_messages"] += 1
            if ns not in self.held and len(self.held) >= HELD_STAMPS:
                del self.held[next(iter(self.held))]
            return self.held.setdefault(ns, Pending(ns, now_ns))
        return self.pending.setdefault(ns, Pending(ns, now_ns))

    def _filled(self, p: Pending, new: bool) -> None:
        """A used stamp's late input (``new``: one it lacked) revises it; a held stamp that is now
        complete: the loop's time jumped there; start again."""
        if p.ns in self.recent:
            if new:
                self.revised.add(p.ns)
            self.counts["late_inputs" if new else "stale_messages"] += 1
            return
        if self.held.get(p.ns) is p and self.complete(p):
            self.pending, self.held = {p.ns: p}, {}
            self.last_ns, self.command_ns = -1, [-1, -1]
            self.newest[:] = -1
            self.commands = [CommandLog(), CommandLog()]
            self.last_applied, self.applying = np.zeros(2), np.ones(2, dtype=bool)
            self.recent, self.revised = {}, set()
            self.counts["time_jumps"] += 1
            self.jumped = True

    def take_jump(self) -> bool:
        """Whether the loop's time jumped since the last call (the filter must start again)."""
        jumped, self.jumped = self.jumped, False
        return jumped

    def _arrived(self, index: int, ns: int) -> None:
        if ns in self.pending:      # a held stamp is no evidence until the loop jumps there
            self.newest[index] = max(self.newest[index], ns)

    def reading(self, channel: int, ns: int, value: float, now_ns: int,
                applied_torque: float = np.nan) -> None:
        """Sensor ``channel`` (index in ``SENSOR_TOPICS``) read ``value`` at stamp ``ns``; the
        encoder also reports the torque applied over the previous period."""
        if (p := self._slot(ns, now_ns)) is not None:
            self._arrived(channel, ns)
            new = not p.present[channel]
            p.values[channel] = value
            p.present[channel] = True
            if channel == ENCODER_CHANNEL:
                p.applied[0] = applied_torque
            self._filled(p, new)

    def applied_force(self, ns: int, value: float, now_ns: int) -> None:
        """The floor-3 force applied over the period before stamp ``ns``."""
        if (p := self._slot(ns, now_ns)) is not None:
            self._arrived(_FORCE, ns)
            new = bool(np.isnan(p.applied[1]))
            p.applied[1] = value
            self._filled(p, new)

    def truth(self, ns: int, physical: np.ndarray, now_ns: int) -> None:
        """The simulator's true physical state at stamp ``ns``."""
        if (p := self._slot(ns, now_ns)) is not None:
            self._arrived(_TRUTH, ns)
            new = p.truth is None and self.needs_truth
            p.truth = physical
            self._filled(p, new)

    def command_received(self, actuator: int, ns: int, value: float) -> bool:
        """A command stamped ``ns``; rejected and counted when non-finite or older than the
        newest one."""
        if not np.isfinite(value) or ns < self.command_ns[actuator]:
            self.counts["rejected_commands"] += 1
            return False
        self.command_ns[actuator] = ns
        self.commands[actuator].record(self.grid.index(ns), value)
        return True

    def in_effect(self, actuator: int, ns: int) -> float:
        """The command the simulator applies over the period before stamp ``ns``: the one
        answering stamp ns − (1 + d) periods, or the newest before it (held), 0 before any."""
        return self.commands[actuator].in_effect(self.grid.index(ns) - self.answer_lag)

    # -- stepping ------------------------------------------------------------------------
    def complete(self, p: Pending) -> bool:
        """Every input of the stamp arrived."""
        return (bool(p.present.all()) and (p.truth is not None or not self.needs_truth)
                and (not self.needs_force or not np.isnan(p.applied[1])))

    def lost(self, p: Pending) -> bool:
        """Every input ``p`` lacks has brought a newer stamp on its own topic, so its message for
        ``p`` will not come."""
        missing = [*np.flatnonzero(~p.present)]
        if self.needs_truth and p.truth is None:
            missing.append(_TRUTH)
        if self.needs_force and np.isnan(p.applied[1]):
            missing.append(_FORCE)
        return bool((self.newest[missing] > p.ns).all())

    def command_in(self) -> bool:
        """In lock-step, the answer to the previous stamp has arrived (or none is expected)."""
        return (not self.lockstep or self.active is None or self.last_ns < 0
                or self.command_ns[self.active] >= self.last_ns)

    def pop_ready(self, now_ns: int) -> Ready | None:
        """The oldest stamp if it is ready to use (removed from the pending ones), else None.
        Call :meth:`used` once it has been used."""
        if not self.pending:
            return None
        p = self.pending[min(self.pending)]
        newer = len(self.pending) > 1 and self.lost(p)
        timed_out = self.wait_ns is not None and now_ns - p.first_ns >= self.wait_ns
        complete = self.complete(p)
        command_in = self.command_in()
        if not (newer or timed_out or (complete and command_in)):
            return None
        self.counts["command_waits_timed_out"] += complete and not command_in
        self.counts["partial_updates"] += not complete
        del self.pending[p.ns]
        ready = Ready(p.ns, self._sample(p), self._control(p), complete, p.first_ns)
        if self.revisable and not complete:
            self.recent[p.ns] = (p, ready)
        return ready

    def _sample(self, p: Pending) -> Sample:
        return Sample(self.grid.seconds(p.ns), p.values[:4].copy(), float(p.values[4]),
                      p.present.copy(), p.truth)

    def take_revision(self) -> list[Ready]:
        """The used stamps that late inputs revised since the last call, oldest first, each as it
        now stands: its sample with every input arrived so far, its actuation the simulator's
        report where that came late (else as used)."""
        revised = sorted(ns for ns in self.revised if ns in self.recent)
        self.revised = set()
        out = []
        for ns in revised:
            p, ready = self.recent[ns]
            control = ready.control.copy()
            if self.active is not None and math.isfinite(p.applied[self.active]):
                control[self.active] = p.applied[self.active]
            out.append(Ready(ns, self._sample(p), control, self.complete(p), p.first_ns))
        return out

    def _control(self, p: Pending) -> np.ndarray:
        """The actuation in effect over the period before ``p``: what the simulator reports it
        applied. Where that report was lost: the command in effect (:meth:`in_effect`) while
        the simulator's last report of a non-zero command showed it applying the commands, else
        that report held (it saturates, holds or zeroes them: a command is then no evidence, and
        taking it would let the estimator and the controller feed each other). Zero for the actuator
        not driven."""
        index = self.grid.index(p.ns) - self.answer_lag
        control = np.zeros(2)
        for i, log in enumerate(self.commands):
            commanded = log.in_effect(index)
            applied = float(p.applied[i])
            reported = math.isfinite(applied)
            # a zero command applied as zero tells nothing (the controller's watchdog sends zero)
            if reported and commanded != 0.0:      # np.isclose(applied, commanded), in floats
                self.applying[i] = abs(applied - commanded) <= ATOL + RTOL * abs(commanded)
            if i == self.active:
                control[i] = (applied if reported else commanded if self.applying[i]
                              else self.last_applied[i])
            log.forget_before(index)    # stamps are used in order: none looks further back
        self.last_applied = control
        self.counts["applied_reported"] += math.isfinite(p.applied[self.active or 0])
        return control

    def used(self, ns: int) -> None:
        """The stamp ``ns`` went into the estimate: older messages are stale from now on, but for
        those that revise one of the last ``revisable`` stamps."""
        self.last_ns = ns
        if self.recent:
            oldest = self.grid.index(ns) - self.revisable
            for old in [k for k in self.recent if self.grid.index(k) < oldest]:
                del self.recent[old]
                self.revised.discard(old)

    def wait_ns_left(self, now_ns: int) -> int | None:
        """Nanoseconds until the first pending stamp times out (None: nothing pending, or no
        time limit)."""
        if not self.pending or self.wait_ns is None:
            return None
        first = min(p.first_ns for p in self.pending.values())
        return max(0, first + self.wait_ns - now_ns)
