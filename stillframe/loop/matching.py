"""Each state estimate matched with the excitation force measured at its stamp (controller_node;
docs/nodes.md, lock-step protocol, step 4). No clock is read here: the caller passes ``now_ns``
(monotonic nanoseconds in the node, any integer in a test).

In lock-step an estimate waits for the load-cell reading of its stamp, as long as it takes (the
simulator publishes the next sample only once this one is answered, so the reading comes unless
the simulator is gone); with a ``wait_ns`` it waits at most that long after the estimate arrived,
then takes the newest reading (counted in ``force_waits_timed_out``). In real time it takes the
reading of its stamp if there is one, else the newest at once.

A load-cell stamp that is negative or more than :data:`~stillframe.loop.assembly.JUMP_NS` after
the newest stamp seen is rejected and counted (``rejected_force_stamps``). An estimate stamped
at or before the last one is stale, unless a load-cell reading of its stamp has arrived since
the last estimate answered:
then the loop's time went back (a restarted simulator), and the matching starts again there
(``time_jumps``; :meth:`ForceMatching.take_jump` tells the caller).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stillframe.loop.assembly import JUMP_NS

#: Load-cell readings kept for matching estimates by stamp.
FORCES_KEPT = 256


@dataclass
class Matched:
    """An estimate (its stamp and physical state) with the force to control it with."""

    ns: int
    physical: np.ndarray
    force: float
    arrival_ns: int = 0
    """When the estimate arrived (the caller's ``now_ns``)."""
    applied: np.ndarray | None = None
    """The [torque, force] the estimate took as applied over the period before it."""


class ForceMatching:
    """Estimates waiting for their load-cell reading, answered in stamp order."""

    def __init__(self, wait_ns: int | None, lockstep: bool, kept: int = FORCES_KEPT) -> None:
        self.wait_ns = wait_ns
        self.lockstep = lockstep
        self.kept = kept
        self.forces: dict[int, float] = {}
        self.force = 0.0            # the newest finite reading
        self.sample_ns = -1         # the newest load-cell stamp: the newest sample time seen
        #: (ns, physical, arrival ns, applied)
        self.pending: list[tuple[int, np.ndarray, int, np.ndarray | None]] = []
        self.last_ns = -1           # the newest estimate accepted
        self.jumped = False
        self.counts = {"stale_estimates": 0, "rejected_estimates": 0,
                       "force_waits_timed_out": 0, "rejected_force_stamps": 0, "time_jumps": 0}

    def add_force(self, ns: int, value: float) -> None:
        """The load cell read ``value`` at stamp ``ns`` (a non-finite reading is ignored)."""
        if not np.isfinite(value):
            return
        newest = max(self.sample_ns, self.last_ns)
        if ns < 0 or (newest >= 0 and ns > newest + JUMP_NS):
            self.counts["rejected_force_stamps"] += 1
            return
        if ns >= self.sample_ns:        # the newest reading; an older or stray one is not
            self.force = value
        self.forces[ns] = value
        self.sample_ns = max(self.sample_ns, ns)
        if len(self.forces) > self.kept:
            self.forces.pop(next(iter(self.forces)))

    def add_estimate(self, ns: int, physical: np.ndarray, now_ns: int,
                     applied: np.ndarray | None = None) -> None:
        """An estimate stamped ``ns`` arrived (with the actuation it took as ``applied``); one
        not newer than the last, or non-finite, is rejected and counted."""
        first = self.pending[0][0] if self.pending else self.last_ns + 1
        if ns < first and ns in self.forces:     # the loop started again at ns
            self.pending, self.last_ns, self.jumped = [], -1, True
            self.forces = {k: v for k, v in self.forces.items() if ns <= k <= ns + JUMP_NS}
            self.sample_ns = max(self.forces)
            self.counts["time_jumps"] += 1
        if ns <= self.last_ns:
            self.counts["stale_estimates"] += 1
        elif not np.all(np.isfinite(physical)):
            self.counts["rejected_estimates"] += 1
        else:
            self.pending.append((ns, physical, now_ns, applied))
            self.last_ns = ns

    def take_jump(self) -> bool:
        """Whether the loop's time went back since the last call."""
        jumped, self.jumped = self.jumped, False
        return jumped

    @property
    def waiting(self) -> bool:
        """An estimate has not been answered yet."""
        return bool(self.pending)

    def pop_ready(self, now_ns: int) -> Matched | None:
        """The oldest estimate with its force, when it may be answered now (else None)."""
        if not self.pending:
            return None
        ns, physical, arrival, applied = self.pending[0]
        if ns not in self.forces:
            if self.lockstep and (self.wait_ns is None or now_ns - arrival < self.wait_ns):
                return None
            self.counts["force_waits_timed_out"] += self.lockstep
        self.pending.pop(0)
        force = self.forces.get(ns, self.force)
        self.forces = {k: v for k, v in self.forces.items() if k > ns}
        return Matched(ns, physical, force, arrival, applied)

    def wait_ns_left(self, now_ns: int) -> int | None:
        """Nanoseconds until the oldest estimate stops waiting for its force (None: none waits
        for a force)."""
        if not self.pending or not self.lockstep or self.wait_ns is None:
            return None
        return max(0, self.pending[0][2] + self.wait_ns - now_ns)
