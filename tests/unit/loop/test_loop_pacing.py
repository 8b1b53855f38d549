"""The simulator's timing (stillframe.loop.pacing) on a fake clock: due times, deadlines,
overruns, lateness and misses in real time and lock-step (docs/nodes.md, real-time mode)."""

from __future__ import annotations

from stillframe.loop.pacing import Pacer

PERIOD_NS = 1_000_000
TIMEOUT_NS = 1_000_000_000
START = 7_000


def test_an_overrun_is_a_start_more_than_a_period_late() -> None:
    p = Pacer(PERIOD_NS, lockstep=False, timeout_ns=TIMEOUT_NS)
    p.start(START)
    assert p.due_ns(3) == START + 3 * PERIOD_NS
    p.begin(0, START)
    p.begin(1, p.due_ns(1) + PERIOD_NS)                # exactly a period late: not an overrun
    assert p.counts["overruns"] == 0 and p.max_lateness_ns == PERIOD_NS
    p.begin(2, p.due_ns(2) + PERIOD_NS + 1)
    assert p.counts["overruns"] == 1 and p.max_lateness_ns == PERIOD_NS + 1
    assert p.deadline_ns(2, p.due_ns(2) + 5) == p.due_ns(3)   # the next sample's due time
    p.missed()
    assert p.counts == {"lockstep_timeouts": 0, "deadline_misses": 1, "overruns": 1}


def test_a_slow_step_overruns_every_later_sample() -> None:
    """Each step takes three periods (a slow integration, injected on the fake clock): from
    sample 1 on every sample starts 2k periods late, so n - 1 overruns, and the worst lateness
    is that of the last sample."""
    p = Pacer(PERIOD_NS, lockstep=False, timeout_ns=TIMEOUT_NS)
    now, n = START, 20
    p.start(now)
    for k in range(n):
        now = max(now, p.due_ns(k))                     # the node sleeps until the due time
        p.begin(k, now)
        now += 3 * PERIOD_NS
    assert p.counts["overruns"] == n - 1
    assert p.max_lateness_ns == 2 * (n - 1) * PERIOD_NS


def test_a_loop_that_keeps_up_never_overruns() -> None:
    p = Pacer(PERIOD_NS, lockstep=False, timeout_ns=TIMEOUT_NS)
    p.start(START)
    for k in range(50):
        p.begin(k, p.due_ns(k) + PERIOD_NS // 2)
    assert p.counts["overruns"] == 0 and p.max_lateness_ns == PERIOD_NS // 2


def test_lockstep_waits_the_timeout_from_publishing_and_ignores_lateness() -> None:
    p = Pacer(PERIOD_NS, lockstep=True, timeout_ns=TIMEOUT_NS)
    p.start(START)
    p.begin(5, START + 1_000 * PERIOD_NS)               # far behind the wall clock: no matter
    assert p.counts["overruns"] == 0 and p.max_lateness_ns == 0
    assert p.deadline_ns(5, 123_456) == 123_456 + TIMEOUT_NS
    p.missed()
    assert p.counts == {"lockstep_timeouts": 1, "deadline_misses": 0, "overruns": 0}


def test_lockstep_gives_sample_0_the_start_up_wait_when_set() -> None:
    p = Pacer(PERIOD_NS, lockstep=True, timeout_ns=TIMEOUT_NS)
    assert p.deadline_ns(0, 7) == 7 + TIMEOUT_NS       # not set: the peers never matched
    p.first_timeout_ns = 30 * TIMEOUT_NS
    assert p.deadline_ns(0, 7) == 7 + 30 * TIMEOUT_NS
    assert p.deadline_ns(1, 7) == 7 + TIMEOUT_NS
    p.first_timeout_ns = TIMEOUT_NS // 2                # never shorter than the lock-step wait
    assert p.deadline_ns(0, 7) == 7 + TIMEOUT_NS
    real_time = Pacer(PERIOD_NS, lockstep=False, timeout_ns=TIMEOUT_NS)
    real_time.first_timeout_ns = 30 * TIMEOUT_NS        # real time: the due time rules
    real_time.start(START)
    assert real_time.deadline_ns(0, START) == START + PERIOD_NS
