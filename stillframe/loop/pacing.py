"""The simulator's timing per sample (sim_node; docs/nodes.md, lock-step protocol and real-time
mode), with no clock: every call that needs the time takes ``now_ns`` (monotonic nanoseconds in
the node, any integer in a test).

- lock-step: the command for sample k is awaited until ``timeout_ns`` after the sample was
  published; a command not in by then is a ``lockstep_timeouts``. Sample 0's command may be
  given longer (``first_timeout_ns``): its round trip ends the start-up (:meth:`Pacer.deadline_ns`).
- real time: sample k is due ``k · period_ns`` after the start and its command by the next due
  time, else a ``deadline_misses``; a sample that starts more than a period late is an
  ``overruns``, and the worst start delay is ``max_lateness_ns``.
"""

from __future__ import annotations

from collections.abc import Callable


class Pacer:
    """Due times, deadlines and what was missed, for one run."""

    def __init__(self, period_ns: int, lockstep: bool, timeout_ns: int) -> None:
        self.period_ns = period_ns
        self.lockstep = lockstep
        self.timeout_ns = timeout_ns
        #: how long sample 0's command is awaited in lock-step (None: ``timeout_ns``)
        self.first_timeout_ns: int | None = None
        self.started_ns = 0
        self.max_lateness_ns = 0
        self.counts = {"lockstep_timeouts": 0, "deadline_misses": 0, "overruns": 0}

    def start(self, now_ns: int) -> None:
        """Sample 0 is due now."""
        self.started_ns = now_ns

    def due_ns(self, k: int) -> int:
        """When sample k is due in real time."""
        return self.started_ns + k * self.period_ns

    def begin(self, k: int, now_ns: int) -> None:
        """Sample k starts now: in real time, count its lateness."""
        if self.lockstep:
            return
        lateness = now_ns - self.due_ns(k)
        self.max_lateness_ns = max(self.max_lateness_ns, lateness)
        self.counts["overruns"] += lateness > self.period_ns

    def deadline_ns(self, k: int, now_ns: int) -> int:
        """Until when the command for sample k (published at ``now_ns``) is awaited.

        In lock-step, sample 0's round trip is the last step of the start-up handshake: DDS
        matches each side on its own, and no node sees from its side whether the remote reader
        has matched its writer yet. A sample the writer sent before that is not lost on a
        reliable topic, but it comes late, when the writer repairs it: 100–150 ms on Fast DDS on
        this machine, measured with a writer that publishes the moment it matches. So sample 0
        is awaited up to ``first_timeout_ns`` when it is set."""
        if not self.lockstep:
            return self.due_ns(k + 1)
        first = self.first_timeout_ns if k == 0 else None
        return now_ns + (self.timeout_ns if first is None else max(first, self.timeout_ns))

    def missed(self) -> None:
        """The command for the current sample did not come by its deadline."""
        self.counts["lockstep_timeouts" if self.lockstep else "deadline_misses"] += 1


def wait_until(due_ns: int, now_ns: Callable[[], int], wait: Callable[[float], None],
               spin_margin_ns: int = 0, running: Callable[[], bool] = lambda: True) -> None:
    """Block in ``wait(seconds)`` (which handles messages meanwhile) until ``spin_margin_ns``
    before ``due_ns``, then poll with ``wait(0)`` until it: a sleep wakes up tens of µs late
    (timer slack, the scheduler), a poll does not (docs/realtime.md)."""
    while running() and (left := due_ns - now_ns()) > 0:
        wait(max(left - spin_margin_ns, 0) * 1e-9)
