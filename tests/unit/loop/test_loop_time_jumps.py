"""The loop's time going back (a restarted simulator) or jumping far ahead, and stray stamps on
one topic, in the sample assembly and the force matching (issue 11, items 3 and 5)."""

from __future__ import annotations

import numpy as np

from stillframe.contract.codecs import SENSOR_TOPICS, SampleGrid
from stillframe.loop.assembly import HELD_STAMPS, JUMP_NS, SampleAssembly
from stillframe.loop.matching import ForceMatching

PERIOD_NS = 31_250_000
WAIT_NS = 500_000_000
STATE = np.arange(8.0)


def _run(a: SampleAssembly, ks: range) -> None:
    """Complete stamps ``ks`` used in order (commands answering each)."""
    for k in ks:
        for c in range(5):
            a.reading(c, k * PERIOD_NS, float(k), 0)
        ready = a.pop_ready(0)
        assert ready is not None and ready.ns == k * PERIOD_NS
        a.used(ready.ns)
        a.command_received(0, ready.ns, 0.5)


def test_a_whole_sample_stamped_back_at_zero_starts_the_assembly_again() -> None:
    a = SampleAssembly(SENSOR_TOPICS, 0, SampleGrid(PERIOD_NS * 1e-9), WAIT_NS, True)
    _run(a, range(0, 10))
    for c in range(4):                                   # the restarted sim's sample 0
        a.reading(c, 0, -1.0, 0)
        assert a.pop_ready(0) is None and not a.take_jump()
    a.reading(4, 0, -1.0, 0)                             # its last input: a whole sample
    assert a.take_jump() and not a.take_jump()
    ready = a.pop_ready(0)                               # used at once, no command awaited
    assert ready.ns == 0 and ready.complete and ready.sample.t == 0.0
    np.testing.assert_array_equal(ready.sample.measurements, [-1.0] * 4)
    assert a.counts["time_jumps"] == 1 and a.counts["stale_messages"] == 5


def test_stray_stamps_on_one_topic_are_counted_and_change_nothing() -> None:
    a = SampleAssembly(SENSOR_TOPICS, 0, SampleGrid(PERIOD_NS * 1e-9), WAIT_NS, False)
    _run(a, range(0, 3))
    far = 2 * PERIOD_NS + JUMP_NS + 1
    for i in range(3 * HELD_STAMPS):                     # zero, negative, far future, many
        a.reading(3, 0, 9.0, 0)
        a.reading(3, -5_000_000_000, 9.0, 0)
        a.reading(3, far + i, 9.0, 0)
    assert len(a.held) <= HELD_STAMPS and not a.pending and not a.take_jump()
    assert a.counts["negative_stamps"] == 3 * HELD_STAMPS
    assert a.counts["future_stamps"] == 3 * HELD_STAMPS
    assert a.counts["stale_messages"] == 3 * HELD_STAMPS
    _run(a, range(3, 5))                                 # the real samples still go through


def test_a_whole_sample_far_ahead_is_a_jump_and_a_stamp_just_ahead_is_not() -> None:
    a = SampleAssembly(SENSOR_TOPICS, 0, SampleGrid(PERIOD_NS * 1e-9), WAIT_NS, False)
    _run(a, range(0, 2))
    a.reading(0, PERIOD_NS + JUMP_NS, 1.0, 0)            # exactly the limit: taken
    assert PERIOD_NS + JUMP_NS in a.pending
    far = 100 * JUMP_NS
    for c in range(5):
        a.reading(c, far, 1.0, 0)
    assert a.take_jump() and list(a.pending) == [far] and a.counts["future_stamps"] == 5


def test_matching_starts_again_when_an_estimate_goes_back_with_its_load_cell() -> None:
    m = ForceMatching(WAIT_NS, lockstep=True)
    for k in range(10):
        m.add_force(k * PERIOD_NS, float(k))
        m.add_estimate(k * PERIOD_NS, STATE, now_ns=0)
        assert m.pop_ready(0).force == float(k)
    m.add_estimate(0, STATE, now_ns=0)                   # no load cell at 0 since: stale
    assert m.counts["stale_estimates"] == 1 and not m.take_jump()
    m.add_force(0, -3.0)                                 # the restarted sim's sample 0
    m.add_estimate(0, STATE, now_ns=0)
    assert m.take_jump() and m.counts["time_jumps"] == 1
    got = m.pop_ready(0)
    assert got.ns == 0 and got.force == -3.0
    assert m.sample_ns == 0


def test_matching_rejects_far_future_and_negative_load_cell_stamps() -> None:
    m = ForceMatching(WAIT_NS, lockstep=False)
    m.add_force(0, 1.0)
    m.add_estimate(0, STATE, now_ns=0)
    m.add_force(JUMP_NS + 1, 1e3)
    m.add_force(-1, 1e3)
    assert m.counts["rejected_force_stamps"] == 2 and m.sample_ns == 0 and m.force == 1.0
    assert m.pop_ready(0).force == 1.0
    m.add_force(PERIOD_NS, 2.0)
    m.add_force(0, 1e3)                                  # a stray stamp 0: not the newest
    assert m.force == 2.0
