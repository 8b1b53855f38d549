"""The simulator's timing per sample (sim_node; docs/nodes.md, lock-step protocol and real-time
mode), with no clock: every call that needs the time takes ``now_ns`` (monotonic nanoseconds in
the node, any integer in a test).

- lock-step: no due times and no deadlines: every sample waits for its command (sim_node ends
  the run when a peer leaves the graph instead).
- real time: sample k is due ``k · period_ns`` after the start and its command by the next due
  time, else a ``deadline_misses``; a sample that starts more than a period late is an
  ``overruns``, and the worst start delay is ``max_lateness_ns``.
"""

from __future__ import annotations

from collections.abc import Callable


class Pacer:
    """Due times, deadlines and what was missed, for one run."""

    def __init__(self, period_ns: int, lockstep: bool) -> None:
        self.period_ns = period_ns
        self.lockstep = lockstep
        self.started_ns = 0
        self.max_lateness_ns = 0
        self.counts = {"deadline_misses": 0, "overruns": 0}

    def start(self, now_ns: int) -> None:
        """Sample 0 is due now."""
        self.started_ns = now_ns

    def due_ns(self, k: int) -> int:
        """When sample k is due in real time (its command is due by sample k + 1's)."""
        return self.started_ns + k * self.period_ns

    def begin(self, k: int, now_ns: int) -> None:
        """Sample k starts now: in real time, count its lateness."""
        if self.lockstep:
            return
        lateness = now_ns - self.due_ns(k)
        self.max_lateness_ns = max(self.max_lateness_ns, lateness)
        self.counts["overruns"] += lateness > self.period_ns

    def missed(self) -> None:
        """Real time: the command for the current sample did not come by its deadline."""
        self.counts["deadline_misses"] += 1


def wait_until(due_ns: int, now_ns: Callable[[], int], wait: Callable[[float], None],
               spin_margin_ns: int = 0, running: Callable[[], bool] = lambda: True) -> None:
    """Block in ``wait(seconds)`` (which handles messages meanwhile) until ``spin_margin_ns``
    before ``due_ns``, then poll with ``wait(0)`` until it: a sleep wakes up tens of µs late
    (timer slack, the scheduler), a poll does not (docs/realtime.md)."""
    while running() and (left := due_ns - now_ns()) > 0:
        wait(max(left - spin_margin_ns, 0) * 1e-9)
