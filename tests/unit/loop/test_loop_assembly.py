"""Sample assembly (stillframe.loop.assembly) on a fake clock: which stamp is used when, with what,
and what is counted (docs/nodes.md, lock-step protocol step 3 and real-time mode)."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.contract import topics
from stillframe.contract.codecs import ENCODER_CHANNEL, SENSOR_TOPICS, SampleGrid
from stillframe.loop.assembly import SampleAssembly
from stillframe.loop.wiring import estimator_inputs
from tests.support.scenes import thesis_scene

PERIOD = 1 / 32
PERIOD_NS = 31_250_000
WAIT_NS = 500_000_000           # half of the default lock-step timeout
READINGS = [0.1, -0.2, 0.3, 0.04, 1.5]   # a1, a2, a3, φ, load cell


def _assembly(lockstep: bool = True, inputs: tuple = SENSOR_TOPICS,
              active: int | None = 0, delay_periods: int = 0) -> SampleAssembly:
    return SampleAssembly(inputs, active, SampleGrid(PERIOD), WAIT_NS, lockstep, delay_periods)


def _feed(a: SampleAssembly, k: int, now_ns: int, channels: range | list = range(5),
          torque: float = 0.0) -> None:
    for c in channels:
        a.reading(c, k * PERIOD_NS, READINGS[c] + k, now_ns, torque)


def test_complete_stamp_is_used_at_once_with_the_exact_sample_time() -> None:
    a = _assembly()
    _feed(a, 3, now_ns=10, channels=range(4))
    assert a.pop_ready(11) is None                       # the load cell is still missing
    _feed(a, 3, now_ns=12, channels=[4], torque=0.0)
    ready = a.pop_ready(12)
    assert ready is not None and ready.complete and ready.ns == 3 * PERIOD_NS
    assert ready.sample.t == 3 * PERIOD                  # the grid's time, not ns · 1e-9
    np.testing.assert_array_equal(ready.sample.measurements, np.add(READINGS[:4], 3))
    assert ready.sample.force == READINGS[4] + 3 and ready.sample.present.all()
    assert a.counts["partial_updates"] == 0 and not a.pending


def test_missing_channel_is_used_as_partial_after_exactly_the_timeout() -> None:
    a = _assembly()
    first = 1_000
    a.reading(0, 0, READINGS[0], first)                 # the stamp's first message
    _feed(a, 0, now_ns=first + 7_000, channels=[1, 2, 4])   # the encoder never comes
    assert a.wait_ns_left(first + 7_000) == WAIT_NS - 7_000   # counted from the first message
    assert a.pop_ready(first + WAIT_NS - 1) is None
    ready = a.pop_ready(first + WAIT_NS)
    assert ready is not None and not ready.complete
    np.testing.assert_array_equal(ready.sample.present, [True, True, True, False, True])
    assert np.isnan(ready.sample.measurements[ENCODER_CHANNEL])
    assert a.counts["partial_updates"] == 1
    assert a.wait_ns_left(first + WAIT_NS) is None


def test_stale_stamps_are_rejected_and_counted() -> None:
    a = _assembly(lockstep=False)
    _feed(a, 5, now_ns=0)
    ready = a.pop_ready(0)
    a.used(ready.ns)
    a.reading(0, 5 * PERIOD_NS, 9.0, 1)                  # the stamp just used
    a.reading(1, 4 * PERIOD_NS, 9.0, 1)                  # an older one
    a.truth(4 * PERIOD_NS, np.zeros(8), 1)
    a.applied_force(5 * PERIOD_NS, 1.0, 1)
    assert a.counts["stale_messages"] == 4 and not a.pending
    assert a.pop_ready(10 * WAIT_NS) is None


@pytest.mark.parametrize("lockstep", [True, False])
def test_only_a_newer_stamp_on_the_missing_inputs_own_topic_ends_the_wait(lockstep: bool) -> None:
    """Topics are not ordered among themselves: stamp 1 on the other topics leaves stamp 0
    waiting for its load cell, which arrives after them and is used; stamp 1 on the encoder's
    topic, whose stamp-0 message is lost, then ends the wait at once (partial, long before the
    timeout), and the encoder's late stamp-0 message is stale."""
    a = _assembly(lockstep=lockstep, active=None)
    _feed(a, 0, now_ns=0, channels=[0, 1, 2])           # the encoder's message is lost
    _feed(a, 1, now_ns=5, channels=[0, 1, 2, 4])
    assert a.pop_ready(6) is None                        # stamp 0's load cell is on its way
    _feed(a, 0, now_ns=7, channels=[4])
    assert a.pop_ready(8) is None                        # nothing says the encoder is lost
    _feed(a, 1, now_ns=9, channels=[3])
    ready = a.pop_ready(9)
    assert ready.ns == 0 and not ready.complete
    np.testing.assert_array_equal(ready.sample.present, [True, True, True, False, True])
    assert ready.sample.force == READINGS[4]
    a.used(ready.ns)
    _feed(a, 0, now_ns=10, channels=[3])                 # too late: stale
    ready = a.pop_ready(10)
    assert ready.ns == PERIOD_NS and ready.complete
    assert a.counts["partial_updates"] == 1 and a.counts["stale_messages"] == 1


def test_truth_and_the_applied_force_are_given_up_on_by_their_own_topics() -> None:
    """The inputs beyond the sensors follow the same rule: stamp 1's sensors leave stamp 0
    waiting for its truth and load cell until their own topics bring stamp 1."""
    inputs = (*SENSOR_TOPICS, topics.STATE_TRUTH, topics.FLOOR3_LOAD_CELL)
    a = _assembly(lockstep=False, inputs=inputs, active=None)
    assert a.needs_truth and a.needs_force
    _feed(a, 0, now_ns=0)
    _feed(a, 1, now_ns=1)
    assert a.pop_ready(2) is None
    a.truth(PERIOD_NS, np.zeros(8), 3)
    assert a.pop_ready(3) is None                        # the load cell of stamp 0 may still come
    a.applied_force(PERIOD_NS, 0.5, 4)
    ready = a.pop_ready(4)
    assert ready.ns == 0 and not ready.complete and ready.sample.truth is None


def test_interleaved_stamps_are_assembled_by_stamp() -> None:
    a = _assembly(lockstep=False)
    _feed(a, 1, now_ns=0, channels=[0])                  # stamp 1's first message comes first
    _feed(a, 0, now_ns=1)
    _feed(a, 1, now_ns=2, channels=[1, 2, 3, 4])
    first = a.pop_ready(3)
    a.used(first.ns)
    second = a.pop_ready(3)
    assert (first.ns, second.ns) == (0, PERIOD_NS)
    assert first.complete and second.complete and a.counts["partial_updates"] == 0
    np.testing.assert_array_equal(second.sample.measurements, np.add(READINGS[:4], 1))


def test_lockstep_waits_for_the_answer_to_the_previous_stamp() -> None:
    a = _assembly()
    _feed(a, 0, now_ns=0)
    a.used(a.pop_ready(0).ns)                            # the first stamp waits for no command
    _feed(a, 1, now_ns=100)
    assert a.pop_ready(100) is None                      # complete, but no command stamped t0
    assert a.command_received(0, 0, 0.25)
    ready = a.pop_ready(101)
    assert ready.complete and a.counts["command_waits_timed_out"] == 0
    a.used(ready.ns)
    _feed(a, 2, now_ns=200)                              # the answer to stamp 1 never comes
    assert a.pop_ready(200 + WAIT_NS - 1) is None
    ready = a.pop_ready(200 + WAIT_NS)
    assert ready.complete and a.counts["command_waits_timed_out"] == 1
    assert a.counts["partial_updates"] == 0


def test_realtime_does_not_wait_for_commands() -> None:
    a = _assembly(lockstep=False)
    _feed(a, 0, now_ns=0)
    a.used(a.pop_ready(0).ns)
    _feed(a, 1, now_ns=1)
    assert a.pop_ready(1).complete


def test_control_is_the_applied_torque_else_the_command_in_effect() -> None:
    """The encoder's effort when it carries one; where it was lost, the command answering the
    previous stamp while the simulator's reports matched the commands, and the last report held
    once one did not (the simulator saturated, held or zeroed the command); the floor-3 force
    (not driven) is zero whatever was commanded."""
    a = _assembly(lockstep=False)
    a.command_received(1, 0, 5.0)
    # the simulator applied sample 0's command, zero for sample 3's, then sample 6's again
    # (the zero applied for the zero command before sample 0 tells nothing)
    efforts = [0.0, 0.1, np.nan, np.nan, 0.0, np.nan, np.nan, 0.7, np.nan]
    a.command_received(0, -PERIOD_NS, 0.0)
    controls = []
    for k, effort in enumerate(efforts):
        _feed(a, k, now_ns=0, torque=effort)
        controls.append(a.pop_ready(0).control)
        a.used(k * PERIOD_NS)
        a.command_received(0, k * PERIOD_NS, 0.1 * (k + 1))
    np.testing.assert_allclose(np.array(controls)[:, 0],
                               [0.0, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 0.7, 0.8], atol=1e-15)
    assert not np.array(controls)[:, 1].any()
    assert a.counts["applied_reported"] == 4


@pytest.mark.parametrize(("delay", "expected"), [(0, 5.0), (1, 3.0), (2, 3.0), (3, 2.0)])
def test_without_the_effort_the_command_in_effect_is_the_delayed_one(
        delay: int, expected: float) -> None:
    """With ``actuators.delay_periods`` = d the simulator applies over the period before stamp 6
    the command answering stamp 5 − d; one that never came (4) is held from the one before."""
    a = _assembly(lockstep=False, delay_periods=delay)
    for k in (0, 1, 2, 3, 5):
        a.command_received(0, k * PERIOD_NS, float(k))
    _feed(a, 6, now_ns=0, torque=np.nan)
    np.testing.assert_array_equal(a.pop_ready(0).control, [expected, 0.0])


def test_bad_commands_are_rejected_and_counted() -> None:
    a = _assembly()
    assert a.command_received(0, 2 * PERIOD_NS, 0.1)
    assert not a.command_received(0, PERIOD_NS, 0.2)     # older than the one held
    assert not a.command_received(0, 3 * PERIOD_NS, np.inf)
    assert a.counts["rejected_commands"] == 2
    assert a.in_effect(0, 3 * PERIOD_NS) == 0.1


def test_the_scene_inputs_decide_completeness() -> None:
    """EUK on the floor-3 force with the truth estimator: a stamp also waits for the applied
    force and the truth, and the control is the applied force."""
    scene = thesis_scene("thesis_euk_floor")
    inputs = estimator_inputs(scene)
    assert inputs == (*SENSOR_TOPICS, topics.FLOOR3_LOAD_CELL, topics.STATE_TRUTH)
    a = _assembly(lockstep=False, inputs=inputs, active=1)
    _feed(a, 0, now_ns=0, torque=0.5)
    assert a.pop_ready(1) is None
    a.applied_force(0, -2.0, 2)
    assert a.pop_ready(3) is None
    truth = np.arange(8.0)
    a.truth(0, truth, 4)
    ready = a.pop_ready(4)
    assert ready.complete and ready.sample.truth is truth
    np.testing.assert_array_equal(ready.control, [0.0, -2.0])   # the torque is not driven
