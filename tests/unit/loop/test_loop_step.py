"""One sample period of the loop (:class:`stillframe.loop.step.LoopStep`) without middleware: a
missed command, the safe state, a gated writer, a refused value, the miss-rate guard and the
actuation delay. The reference is a twin plant advanced by hand with the command each rule says
must be applied: the truth of the two must agree to the last bit."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.loop.spec import LoopSpec
from stillframe.loop.step import LoopStep
from stillframe.loop.writer_gate import WriterGate
from stillframe.plant.frame_plant import make_plant
from tests.support.scenes import lumped_scene

#: LQG on the pendulum torque with a 0.5 N m saturation, 32 Hz, 2 s
OVERRIDES = ["duration=2", "controller.type=lqg", "estimator.type=kf", "controller.start=1",
             "evaluation.window=0.5", "actuators.torque_limit=0.5"]
CONTROLLER, ROGUE = b"controller-gid-16", b"rogue-gid-16byte"


def _twins(mode: str, *extra: str, writers=(None, None), **spec_options):
    scene = lumped_scene([*OVERRIDES, *extra])
    spec = LoopSpec.of(scene, mode=mode, **spec_options)
    return spec, LoopStep(spec, make_plant(scene), writers), make_plant(scene)


def _run(step: LoopStep, reference, commands, missed=lambda k: False):
    """Each period: the command ``commands[k]`` offered (None: none comes), the period
    advanced; the reference plant is advanced with what :meth:`LoopStep.advance` says it
    applied. Returns the applied torques."""
    applied = []
    for k, value in enumerate(commands):
        step.sample()
        reference.sample()
        if value is not None:
            step.offer(0, value, step.now_ns)
        period = step.advance(missed=missed(k) or value is None)
        applied.append(period.command[0])
        reference.advance(period.command)
        assert np.array_equal(step.plant.sample().truth, reference.sample().truth)
    return np.array(applied)


def test_a_missed_command_is_held_until_the_safe_state() -> None:
    """Real time, commands 0.1, 0.2, then none: 0.2 is held for the periods until it is
    ``command_timeout_periods`` (3) old, then zero (the safe state), counted."""
    spec, step, reference = _twins("realtime", command_miss_limit=0.0)
    torques = _run(step, reference, [0.1, 0.2, None, None, None, None, 0.3])
    np.testing.assert_array_equal(torques, [0.1, 0.2, 0.2, 0.2, 0.0, 0.0, 0.3])
    assert step.counts["safe_state_samples"] == 2
    assert spec.command_timeout_periods == 3


def test_a_command_from_another_writer_is_refused_before_its_value() -> None:
    """The command topic's writer gate pins ``controller_node``: the rogue writer's command is
    refused (counted) and the controller's taken."""
    graph = [(CONTROLLER, "/frame/controller_node"), (ROGUE, "/rogue")]
    gate = WriterGate("controller_node", lambda: graph)
    _, step, _ = _twins("lockstep", writers=(gate, None))
    step.sample()
    assert not step.admits(0, ROGUE)
    assert step.admits(0, CONTROLLER) and step.offer(0, 0.25, step.now_ns)
    assert step.answered and step.counts["rejected_commands"] == 1
    assert step.advance().command[0] == 0.25
    assert step.gate_reports(["torque", "force"])["torque"]["rejected_second_writer"] == 1


@pytest.mark.parametrize(("value", "stamp", "reason"), [
    (float("nan"), 0, "non_finite"), (0.51, 0, "beyond_limit"), (0.1, 1, "future_stamp")])
def test_a_bad_command_is_refused_and_the_held_one_applied(value, stamp, reason) -> None:
    """Beyond the actuator's 0.5 N m saturation (its bound), not finite, or stamped after the
    current sample: refused, counted by reason; the command held (0.2) is applied."""
    _, step, reference = _twins("realtime", command_miss_limit=0.0)
    _run(step, reference, [0.2])
    step.sample()
    assert not step.offer(0, value, step.now_ns + stamp * step.spec.period_ns)
    assert not step.answered
    assert step.advance(missed=True).command[0] == 0.2
    assert step.gates[0].rejected[reason] == 1 and step.counts["rejected_commands"] == 1


def test_the_guard_zeroes_the_actuation_while_too_many_commands_miss() -> None:
    """At 32 Hz the guard looks back over 32 samples with a limit of 0.25: the 9th miss in a row
    trips it (9/32 > 0.25), zero actuation is applied although commands come again, until no
    more than 4 of the last 32 samples missed (half the limit)."""
    spec, step, reference = _twins("realtime", "controller.limit=0.3",
                                   command_timeout_periods=1000)
    assert spec.miss_window == 32
    commands = [0.3] * 4 + [None] * 10 + [0.3] * 30
    torques = _run(step, reference, commands)
    assert list(torques[:12]) == [0.3] * 12           # held: 8 misses, 8/32 = 0.25
    assert torques[12] == 0.0                          # the 9th miss trips the guard
    tripped = np.flatnonzero(torques == 0.0)
    # misses at samples 4-13: the last 32 samples hold 4 of them (10-13) from sample 41 on
    np.testing.assert_array_equal(tripped, np.arange(12, 41))
    assert step.counts["degraded_samples"] == len(tripped)


def test_lockstep_never_trips_the_guard() -> None:
    _, step, reference = _twins("lockstep")
    torques = _run(step, reference, [0.3] * 4 + [None] * 12)
    assert not step.guard.tripped and step.counts["degraded_samples"] == 0
    assert torques[-1] == 0.0 and step.counts["safe_state_samples"] == 10   # the safe state


def test_a_delayed_command_is_applied_d_periods_later() -> None:
    """``actuators.delay_periods=2``: the command answering sample k is applied over period
    k + 2; before period 2 nothing is due (zero)."""
    _, step, reference = _twins("lockstep", "actuators.delay_periods=2")
    torques = _run(step, reference, [0.1, 0.2, 0.3, 0.4, 0.5])
    np.testing.assert_array_equal(torques, [0.0, 0.0, 0.1, 0.2, 0.3])
