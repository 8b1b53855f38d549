"""The simulator's timing (stillframe.loop.pacing) on a fake clock: due times, deadlines,
overruns, lateness and misses in real time and lock-step (docs/nodes.md, real-time mode)."""

from __future__ import annotations

from stillframe.loop.pacing import Pacer

PERIOD_NS = 1_000_000
START = 7_000


def test_an_overrun_is_a_start_more_than_a_period_late() -> None:
    p = Pacer(PERIOD_NS, lockstep=False)
    p.start(START)
    assert p.due_ns(3) == START + 3 * PERIOD_NS
    p.begin(0, START)
    p.begin(1, p.due_ns(1) + PERIOD_NS)                # exactly a period late: not an overrun
    assert p.counts["overruns"] == 0 and p.max_lateness_ns == PERIOD_NS
    p.begin(2, p.due_ns(2) + PERIOD_NS + 1)
    assert p.counts["overruns"] == 1 and p.max_lateness_ns == PERIOD_NS + 1
    p.missed()
    assert p.counts == {"deadline_misses": 1, "overruns": 1}


def test_a_slow_step_overruns_every_later_sample() -> None:
    """Each step takes three periods (a slow integration, injected on the fake clock): from
    sample 1 on every sample starts 2k periods late, so n - 1 overruns, and the worst lateness
    is that of the last sample."""
    p = Pacer(PERIOD_NS, lockstep=False)
    now, n = START, 20
    p.start(now)
    for k in range(n):
        now = max(now, p.due_ns(k))                     # the node sleeps until the due time
        p.begin(k, now)
        now += 3 * PERIOD_NS
    assert p.counts["overruns"] == n - 1
    assert p.max_lateness_ns == 2 * (n - 1) * PERIOD_NS


def test_a_loop_that_keeps_up_never_overruns() -> None:
    p = Pacer(PERIOD_NS, lockstep=False)
    p.start(START)
    for k in range(50):
        p.begin(k, p.due_ns(k) + PERIOD_NS // 2)
    assert p.counts["overruns"] == 0 and p.max_lateness_ns == PERIOD_NS // 2


def test_lockstep_ignores_lateness() -> None:
    """Lock-step has no due times: a sample far behind the wall clock is not late."""
    p = Pacer(PERIOD_NS, lockstep=True)
    p.start(START)
    p.begin(5, START + 1_000 * PERIOD_NS)
    assert p.counts == {"deadline_misses": 0, "overruns": 0} and p.max_lateness_ns == 0
