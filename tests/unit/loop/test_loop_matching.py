"""Force matching (stillframe.loop.matching) on a fake clock: each estimate is answered with the
load-cell reading of its own stamp (docs/nodes.md, lock-step protocol step 4)."""

from __future__ import annotations

import numpy as np

from stillframe.loop.matching import ForceMatching

PERIOD_NS = 31_250_000
WAIT_NS = 250_000_000           # a quarter of the default lock-step timeout
STATE = np.arange(8.0)


def test_each_estimate_gets_the_force_of_its_own_stamp() -> None:
    m = ForceMatching(WAIT_NS, lockstep=True)
    for k, force in enumerate([1.0, 2.0, 3.0]):
        m.add_force(k * PERIOD_NS, force)
    m.add_estimate(PERIOD_NS, STATE, now_ns=0)         # older than the newest reading
    got = m.pop_ready(0)
    assert got.ns == PERIOD_NS and got.force == 2.0 and got.physical is STATE
    assert list(m.forces) == [2 * PERIOD_NS]            # readings up to its stamp are done with
    m.add_estimate(2 * PERIOD_NS, STATE, now_ns=1)
    assert m.pop_ready(1).force == 3.0
    assert m.counts["force_waits_timed_out"] == 0


def test_lockstep_waits_for_the_force_then_takes_the_newest_after_exactly_the_timeout() -> None:
    m = ForceMatching(WAIT_NS, lockstep=True)
    m.add_force(0, 1.0)
    arrival = 5_000
    m.add_estimate(PERIOD_NS, STATE, now_ns=arrival)
    assert m.waiting and m.wait_ns_left(arrival + 1_000) == WAIT_NS - 1_000
    assert m.pop_ready(arrival + WAIT_NS - 1) is None
    m.add_estimate(2 * PERIOD_NS, STATE, now_ns=arrival + 10)   # queued behind it
    m.add_force(2 * PERIOD_NS, 3.0)                     # the next stamp's reading comes first
    got = m.pop_ready(arrival + WAIT_NS)
    assert (got.ns, got.force) == (PERIOD_NS, 3.0)      # the newest reading
    assert m.counts["force_waits_timed_out"] == 1
    assert m.pop_ready(arrival + WAIT_NS).force == 3.0  # its own stamp's reading
    assert not m.waiting and m.wait_ns_left(arrival + WAIT_NS) is None


def test_the_force_arriving_late_is_still_matched() -> None:
    m = ForceMatching(WAIT_NS, lockstep=True)
    m.add_estimate(0, STATE, now_ns=0)
    assert m.pop_ready(WAIT_NS // 2) is None
    m.add_force(0, -4.0)
    assert m.pop_ready(WAIT_NS // 2).force == -4.0
    assert m.counts["force_waits_timed_out"] == 0


def test_realtime_answers_at_once_with_the_newest_force() -> None:
    m = ForceMatching(WAIT_NS, lockstep=False)
    m.add_force(0, 1.5)
    m.add_estimate(PERIOD_NS, STATE, now_ns=0)
    assert m.wait_ns_left(0) is None                    # nothing waits in real time
    got = m.pop_ready(0)
    assert (got.ns, got.force) == (PERIOD_NS, 1.5)
    assert m.counts["force_waits_timed_out"] == 0


def test_stale_and_non_finite_estimates_are_rejected_and_counted() -> None:
    m = ForceMatching(WAIT_NS, lockstep=False)
    m.add_estimate(2 * PERIOD_NS, STATE, now_ns=0)
    m.add_estimate(2 * PERIOD_NS, STATE, now_ns=0)      # the same stamp again
    m.add_estimate(PERIOD_NS, STATE, now_ns=0)          # an older one
    bad = STATE.copy()
    bad[5] = np.nan
    m.add_estimate(3 * PERIOD_NS, bad, now_ns=0)
    assert m.counts["stale_estimates"] == 2 and m.counts["rejected_estimates"] == 1
    assert [e[0] for e in m.pending] == [2 * PERIOD_NS] and m.last_ns == 2 * PERIOD_NS


def test_non_finite_readings_are_ignored_and_the_oldest_dropped_beyond_the_kept() -> None:
    m = ForceMatching(WAIT_NS, lockstep=True, kept=3)
    for k in range(4):
        m.add_force(k * PERIOD_NS, float(k))
    m.add_force(5 * PERIOD_NS, np.nan)
    assert list(m.forces) == [PERIOD_NS, 2 * PERIOD_NS, 3 * PERIOD_NS]
    assert m.force == 3.0 and m.sample_ns == 3 * PERIOD_NS
