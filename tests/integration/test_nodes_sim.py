"""sim_node as a process against a probe in the test process that plays estimator and
controller: the wire content of every contract topic equals the in-process plant's samples
under the same commands; in lock-step a command that does not come ends the run (exit code 7,
the sample named, the partial result kept), and a probe that leaves the graph ends it too."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from stillframe.contract import messages, topics
from stillframe.middleware.api import create_node, spin_until
from stillframe.node_runtime.declarations import ESTIMATOR
from stillframe.node_runtime.support import diagnostic_values
from stillframe.plant.frame_plant import FramePlant
from tests.support.middleware import finish
from tests.support.nodes import params_file, start_node
from tests.support.scenes import thesis_scene
from tests.support.waits import HANG_S

OVERRIDES = ["duration=1", "controller.start=0.5", "evaluation.window=0.25"]  # 32 samples
STEPS = 32
RATE_HZ = 32
SENSORS = (*topics.FLOOR_IMU, topics.PENDULUM_JOINT_STATES, topics.EXCITATION_WRENCH,
           topics.STATE_TRUTH, topics.CLOCK, topics.DIAGNOSTICS)


def torque(k: int) -> float:
    """The probe's answer to sample k (different every step, so a held value shows)."""
    return 0.02 * np.sin(0.7 * k) + 0.01


#: the probe's node name
NAME = ESTIMATOR


class Probe:
    """Raw subscriptions to everything sim_node publishes (decoded with rosbags' typestore
    directly) and a torque publisher answering the first ``answers`` samples. It stands in for
    the estimator and the controller, so it has the estimator's name and the simulator's
    ``command_writer`` pin names it (the simulator starts once its peers, by name, matched)."""

    def __init__(self, answers: int) -> None:
        self.node = create_node(NAME, namespace=topics.DEFAULT_NAMESPACE, argv=["test"])
        self.received: dict[str, list] = {spec.name: [] for spec in SENSORS}
        for spec in SENSORS:
            self.node.create_subscription(
                spec.type_name, spec.name,
                lambda data, _info, spec=spec: self.received[spec.name].append(
                    messages.TYPESTORE.deserialize_cdr(data, spec.type_name)),
                spec.qos, raw=True)
        self.cmd = self.node.create_publisher(topics.TORQUE_CMD.type_name, topics.TORQUE_CMD.name,
                                              topics.TORQUE_CMD.qos)
        self.answers = answers
        # a controller answers once its load cell is in (the last message the loop waits for;
        # state_truth comes after the command, docs/nodes.md, lock-step protocol)
        wrench = topics.EXCITATION_WRENCH      # reliable, as the loop's own readers in lock-step
        self.node.create_subscription(wrench.type_name, wrench.name, self.answer, "default")

    def answer(self, reading: object) -> None:
        k = round(messages.stamp_ns(reading.header.stamp) * 1e-9 * RATE_HZ)
        if k < self.answers:
            msg = messages.new("geometry_msgs/msg/WrenchStamped")
            msg.header.stamp = reading.header.stamp
            msg.wrench.torque.z = torque(k)
            self.cmd.publish(msg)

    def run(self, sim) -> None:
        assert spin_until(self.node, lambda: sim.poll() is not None, HANG_S)
        spin_until(self.node, lambda: False, 0.3)   # the last diagnostics


def _run_sim(tmp_path: Path, answers: int, code: int = 0, leave: bool = False,
             **params: object) -> tuple[Probe, dict, dict, str]:
    """sim_node against the probe; ``leave``: the probe leaves the graph once it has answered
    its samples. Returns the probe, the result, the histories and the sim's log."""
    result = tmp_path / "result.json"
    probe = Probe(answers)
    try:
        sim = start_node("sim_node", params_file(tmp_path, "thesis_lqg", OVERRIDES,
                                                 result_file=str(result), command_writer=NAME,
                                                 **params))
        if leave:
            assert spin_until(probe.node, lambda: len(probe.received["/clock"]) > answers, HANG_S)
            probe.node.destroy_node()
            assert sim.wait(120) is not None
        else:
            probe.run(sim)
        _out, err = finish(sim)
        assert sim.returncode == code, err[-2000:]
    finally:
        if not leave:
            probe.node.destroy_node()
    with np.load(result.with_suffix(".npz")) as data:
        return probe, json.loads(result.read_text()), dict(data), err


def _reference(commands: list[float]) -> list:
    """The in-process plant's samples under the given torque commands."""
    plant = FramePlant(thesis_scene("thesis_lqg", OVERRIDES))
    samples = []
    for u in commands:
        samples.append(plant.sample())
        plant.advance(np.array([u, 0.0]))
    return samples


def test_contract_topics_carry_the_plant_samples(ros_domain: int, tmp_path: Path) -> None:
    probe, result, hist, _ = _run_sim(tmp_path, answers=STEPS)
    commands = [torque(k) for k in range(STEPS)]
    ref = _reference(commands)
    got = probe.received
    stamps = [round(s.t * 1e9) for s in ref]
    assert [messages.stamp_ns(m.clock) for m in got["/clock"]] == stamps
    var = thesis_scene("thesis_lqg").sensors.accelerometer_noise_std ** 2
    for n, spec in enumerate(topics.FLOOR_IMU):
        imus = got[spec.name]
        assert [messages.stamp_ns(m.header.stamp) for m in imus] == stamps
        assert [m.linear_acceleration.x for m in imus] == [s.measurements[n] for s in ref]
        assert all(m.header.frame_id == f"floor{n + 1}" and m.orientation_covariance[0] == -1
                   and m.angular_velocity_covariance[0] == -1
                   and m.linear_acceleration_covariance[0] == var for m in imus)
    enc = got[topics.PENDULUM_JOINT_STATES.name]
    assert [list(m.name) for m in enc] == [["pendulum"]] * STEPS
    assert [m.position[0] for m in enc] == [s.measurements[3] for s in ref]
    wrench = got[topics.EXCITATION_WRENCH.name]
    assert [m.wrench.force.x for m in wrench] == [s.force for s in ref]
    truth = got[topics.STATE_TRUTH.name]
    assert [list(m.name) for m in truth] == [["x1", "x2", "x3", "phi"]] * STEPS
    np.testing.assert_array_equal([np.r_[m.position, m.velocity] for m in truth],
                                  [s.truth for s in ref])
    # The sim applied exactly the commands it received, one per step, no timeouts.
    np.testing.assert_array_equal(hist["command"][:, 0], commands)
    np.testing.assert_array_equal(hist["truth"], [s.truth for s in ref])
    assert result["complete"] is True and result["steps"] == STEPS
    final = diagnostic_values(got["/diagnostics"][-1])
    assert final["step"] == str(STEPS)
    assert got["/diagnostics"][-1].status[0].name == "/frame/sim_node"


def test_a_command_that_never_comes_ends_the_lockstep_run(ros_domain: int,
                                                          tmp_path: Path) -> None:
    """The probe answers 8 samples, then stays on the graph without answering: the simulator
    never advances past sample 8; after ``lockstep_timeout_s`` it ends the run with one line
    naming the sample and the peer, exit code 7, and the 8 samples it ran, bit for bit those
    of the in-process plant under the same commands, marked incomplete."""
    answered = 8
    _, result, hist, err = _run_sim(tmp_path, answers=answered, code=7, lockstep_timeout_s=1.0)
    commands = [torque(k) for k in range(answered)]
    assert result["complete"] is False and result["steps"] == answered
    assert result["error"]["kind"] == "LoopError"
    np.testing.assert_array_equal(hist["command"][:, 0], commands)
    np.testing.assert_array_equal(hist["truth"], [s.truth for s in _reference(commands)])
    line = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(line) == 1 and f"no command for sample {answered} " in line[0], err[-2000:]
    assert f"{NAME} still on the graph" in line[0] and "Traceback" not in err


def test_a_peer_that_leaves_the_graph_ends_the_lockstep_run(ros_domain: int,
                                                            tmp_path: Path) -> None:
    """The probe answers 8 samples and leaves the graph (its node destroyed): the simulator
    waits no longer than its next look at the graph (well before ``lockstep_timeout_s``, 600 s
    here) and ends the run naming the peer that left, exit code 7, the partial result kept."""
    answered = 8
    _, result, hist, err = _run_sim(tmp_path, answers=answered, code=7, leave=True,
                                    lockstep_timeout_s=600.0)
    assert result["complete"] is False and result["steps"] == answered
    commands = [torque(k) for k in range(answered)]
    np.testing.assert_array_equal(hist["truth"], [s.truth for s in _reference(commands)])
    line = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(line) == 1 and "left the graph while sample 8 " in line[0], err[-2000:]
    assert NAME in line[0]


def test_sensor_topics_are_reliable_in_lockstep_only() -> None:
    """A lost best-effort sample would break lock-step's promise of identical numbers."""
    from stillframe.middleware.qos import PROFILES, Reliability
    from stillframe.node_runtime.support import LoopParameters

    scene = thesis_scene("thesis_lqg")
    lockstep = LoopParameters(scene, "lockstep", 1.0)
    realtime = LoopParameters(scene, "realtime", 1.0)
    for spec in (*topics.FLOOR_IMU, topics.PENDULUM_JOINT_STATES, topics.EXCITATION_WRENCH):
        qos = lockstep.qos(spec)
        assert qos.reliability == Reliability.RELIABLE
        assert qos.depth == PROFILES["sensor_data"].depth
        assert realtime.qos(spec) == "sensor_data"
    assert lockstep.qos(topics.STATE_ESTIMATE) == "default"
