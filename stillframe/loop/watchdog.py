"""When the loop falls back to zero actuation: controller_node for want of a fresh estimate
(docs/nodes.md, watchdog), sim_node for want of a fresh command. Both run on sample time, not
wall time. For the controller, ``now_ns`` is the newest sample stamp the node has seen (the
load cell's, or ``/clock`` with ``use_sim_time`` if newer). Staleness itself is the supervisor's
(:meth:`stillframe.control.supervisor.Controller.stale`), so that the node and the control law
agree on it."""

from __future__ import annotations

from collections import deque

from stillframe.contract.codecs import SampleGrid
from stillframe.control.supervisor import Controller


class EstimateWatchdog:
    """Armed by the first estimate the controller used; fires once per sample time while the
    newest estimate is ``watchdog_periods`` periods old or more."""

    def __init__(self, controller: Controller, grid: SampleGrid) -> None:
        self.controller = controller
        self.grid = grid
        self.fired_ns = -1      # the newest sample time a zero command was due at

    def due(self, now_ns: int, waiting: bool) -> float | None:
        """The sample time [s] to command zero at, or None: not armed, no sample time yet
        (``now_ns`` < 0), an estimate still ``waiting`` to be answered, a fresh estimate, or
        already fired at this sample time."""
        if self.controller.latest is None or now_ns < 0 or waiting:
            return None
        t = self.grid.seconds(now_ns)
        if not self.controller.stale(t):
            return None
        ns = self.grid.ns(t)
        if ns <= self.fired_ns:
            return None
        self.fired_ns = ns
        return t


def command_expired(now_ns: int, command_ns: int, limit_ns: int) -> bool:
    """The simulator's safe-state condition (sim_node, ``command_timeout_periods``): at sample
    time ``now_ns`` the newest command taken, stamped ``command_ns`` (-1: none yet, counted from
    0), is ``limit_ns`` or older."""
    return now_ns - max(command_ns, 0) >= limit_ns


class MissRateGuard:
    """The simulator's second safe state (sim_node, ``command_miss_limit``): a control path
    that loses or delays so many commands that the held ones drive the structure rather than
    damp it. Over the last ``window`` samples, once more than ``limit`` of them missed their
    command, zero actuation until no more than ``limit / 2`` do (the hysteresis keeps it from
    flickering at the limit); ``limit`` 0 turns the guard off."""

    def __init__(self, window: int, limit: float) -> None:
        self.window = window
        self.limit = limit
        self._missed: deque[bool] = deque(maxlen=window)
        self.misses = 0
        self.tripped = False

    def record(self, missed: bool) -> bool:
        """One sample more (``missed``: its command was not in time); True while tripped."""
        if len(self._missed) == self.window:
            self.misses -= self._missed[0]
        self._missed.append(missed)
        self.misses += missed
        if self.limit > 0:
            rate = self.misses / self.window
            self.tripped = rate > self.limit if not self.tripped else rate > self.limit / 2
        return self.tripped
