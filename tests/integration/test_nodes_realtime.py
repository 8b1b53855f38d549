"""Real-time mode: the simulator is paced by the wall clock, counts overruns when it cannot keep
up, and the three nodes close the loop; and the nodes' parameter errors and signals."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from sim_node.node import SimNode
from stillframe.contract import topics
from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.middleware.api import create_node, spin_until
from stillframe.node_runtime.declarations import SimParameterValues
from stillframe.node_runtime.support import LoopParameters
from stillframe.plant.frame_plant import FramePlant
from tests.support.middleware import child_env, finish, start_python, wait_for_line
from tests.support.nodes import params_file, run_loop, start_node, stop, wait_for_log
from tests.support.scenes import thesis_scene
from tests.support.waits import HANG_S

OPEN_LOOP = ["controller.type=none", "estimator.type=none"]


def _sim_alone(tmp_path: Path, overrides: list[str]) -> tuple[dict, dict]:
    result = tmp_path / "result.json"
    sim = start_node("sim_node", params_file(tmp_path, "thesis_lqg", overrides, mode="realtime",
                                             result_file=str(result)))
    _out, err = finish(sim, timeout=120)
    assert sim.returncode == 0, err[-2000:]
    with np.load(result.with_suffix(".npz")) as data:
        return json.loads(result.read_text()), dict(data)


def test_realtime_sim_is_paced_by_the_wall_clock(ros_domain: int, tmp_path: Path) -> None:
    overrides = [*OPEN_LOOP, "duration=1"]
    result, hist = _sim_alone(tmp_path, overrides)
    scene = thesis_scene("thesis_lqg", overrides)
    period = 1.0 / scene.sensors.rate_hz
    assert result["steps"] == 32 and result["mode"] == "realtime"
    # Sample k is not taken before k periods of wall time: 31 periods at least (no upper bound
    # is asserted, the machine is shared).
    assert result["wall_s"] >= 31 * period
    plant = FramePlant(scene)
    truth = []
    for _ in range(32):
        truth.append(plant.sample().truth)
        plant.advance(np.zeros(2))
    np.testing.assert_array_equal(hist["truth"], truth)


def test_realtime_sim_counts_overruns_when_it_cannot_keep_up(ros_domain: int) -> None:
    """sim_node in this process, its plant slowed down: every step takes at least three periods
    (a sleep injected before each integration), so from sample 1 on every sample starts at least
    2k periods late: n - 1 overruns at least (n if even sample 0 started late), and the last
    sample at least 2(n - 1) periods late. Bounds from the injected delay, none on the machine."""
    scene = thesis_scene("thesis_lqg", [*OPEN_LOOP, "duration=0.3125"])   # 10 samples
    period, n = 1.0 / scene.sensors.rate_hz, 10
    node = create_node("sim_node", namespace=topics.DEFAULT_NAMESPACE, argv=["test"])
    try:
        sim = SimNode(node, LoopParameters(scene, "realtime", 1.0),
                      {SimParameterValues: SimParameterValues(discovery_timeout_s=5.0)})
        advance = sim.plant.advance

        def slow_advance(control: np.ndarray) -> np.ndarray:
            time.sleep(3 * period)
            return advance(control)

        sim.plant.advance = slow_advance
        history, _ = sim.run()
    finally:
        node.destroy_node()
    result = history.evaluation
    assert result["steps"] == n and result["mode"] == "realtime"
    assert result["overruns"] in (n - 1, n)
    assert result["max_lateness_ms"] >= 1e3 * 2 * (n - 1) * period
    assert result["deadline_misses"] == 0               # no controller: nothing to wait for


#: answers /clock with a 1 N m command for the even samples only, as a lossy control path would
HALF_THE_COMMANDS = """
from stillframe.contract import messages
from stillframe.middleware.api import create_node, spin
node = create_node("lossy_controller", namespace="/frame")
pub = node.create_publisher("geometry_msgs/msg/WrenchStamped", "pendulum/torque_cmd", "default")
def answer(clock):
    ns = messages.stamp_ns(clock.clock)
    if ns // 31_250_000 % 2 == 0:
        msg = messages.new("geometry_msgs/msg/WrenchStamped")
        msg.header.stamp = messages.time_msg(ns)
        msg.wrench.torque.z = 1.0
        pub.publish(msg)
node.create_subscription("rosgraph_msgs/msg/Clock", "/clock", answer, "clock")
print("ready", flush=True)
spin(node)
"""


def test_realtime_sim_holds_zero_while_half_the_commands_miss(ros_domain: int) -> None:
    """A controller whose every other command is missing (``actuators.delay_periods=1``, so the
    sim never waits for one): more than a quarter of the last second's samples (32) missed
    theirs, so the sim's guard trips and applies zero, and with half of them missing for good it
    never recovers. Forced by the commands left out, not by the machine: a slow machine only
    misses more. Before the trip the held 1 N m is applied. The command timeout is set out of
    reach: a commander starved by a loaded machine would otherwise put some samples into the
    safe state (counted apart from the guard's) and this test is about the guard alone."""
    scene = thesis_scene("thesis_lqg", ["duration=2", "controller.start=1",
                                        "evaluation.window=1", "actuators.delay_periods=1"])
    commander = start_python(HALF_THE_COMMANDS)
    node = create_node("sim_node", namespace=topics.DEFAULT_NAMESPACE, argv=["test"])
    try:
        wait_for_line(commander, "ready")
        sim = SimNode(node, LoopParameters(scene, "realtime", 1.0),
                      {SimParameterValues: SimParameterValues(
                          discovery_timeout_s=2.0, command_timeout_periods=1_000_000)})
        # the commander on the simulator's graph (its /clock reader, its command writer) before
        # the run: the simulator's discovery wait is for an estimator and a controller, which
        # this test does not start, and a loaded machine can take longer than it to discover
        command = f"{topics.DEFAULT_NAMESPACE}/pendulum/torque_cmd"
        assert spin_until(node, lambda: bool(node.get_subscriptions_info_by_topic("/clock")
                                             and node.get_publishers_info_by_topic(command)),
                          HANG_S)
        history, _ = sim.run()
    finally:
        node.destroy_node()
        commander.terminate()
        finish(commander)
    result, torque = history.evaluation, history.command[:, 0]
    n = len(torque)
    assert result["deadline_misses"] >= n // 2 - 1
    tripped = int(np.flatnonzero(torque == 1.0)[-1]) + 1     # zero from here to the end
    assert np.all(torque[tripped:] == 0.0) and result["degraded_samples"] == n - tripped
    # 8 misses in 32 samples do not trip it, the 9th does: at the latest after 2 x 9 samples
    # (+1: the delay, +1: the first command) when every odd sample misses
    assert tripped <= 2 * 9 + 2, torque
    assert result["safe_state_samples"] == 0


@pytest.mark.slow
def test_realtime_three_nodes_close_the_loop(ros_domain: int, tmp_path: Path) -> None:
    """LQG at 32 Hz in real time through the three nodes. Nothing here depends on how fast the
    machine is: every sample's command either came before the next sample was due or is a
    deadline miss (the two add up to the steps), and before the controller's start the plant
    gets zero. How close the reductions are to lock-step's depends on the misses: asserted only
    for a run without misses; the speed itself is `bench loop`'s figure."""
    overrides = ["duration=3", "controller.start=1.5", "evaluation.window=1"]
    result, hist = run_loop(tmp_path, "thesis_lqg", overrides, mode="realtime")
    assert result["steps"] == 96 and result["wall_s"] >= 95 / 32
    assert result["commands_in_time"] + result["deadline_misses"] == 96
    if result["commands_in_time"]:
        assert np.isfinite(result["latency_ms"]["p50"])
    start = round(1.5 * 32)
    assert np.count_nonzero(hist["command"][:start, 0]) == 0   # before the start: zero
    if result["deadline_misses"] == 0:      # every command in time: the lock-step loop's law
        reference = run_closed_loop(thesis_scene("thesis_lqg", overrides)).evaluation
        np.testing.assert_allclose(result["reduction_pct"]["displacement"],
                                   reference["reduction_pct"]["displacement"], atol=10.0)


@pytest.mark.parametrize(("package", "args", "message"), [
    ("sim_node", (), "parameter 'scene'"),
    ("estimator_node", ("-p", "mode:=fast"), "parameter 'mode'"),
    ("controller_node", ("-p", "overrides:=[nokey]"), "--set nokey"),
    ("estimator_node", ("-p", "run_token:=12e45"), "parameter 'run_token'"),
    ("container_node", ("-p", "run_token:=12e45"), "parameter 'run_token'"),
])
def test_bad_parameters_exit_2_with_one_line(ros_domain: int, package: str, args: tuple,
                                             message: str) -> None:
    """The three share the parameter code; one wrong parameter each, and one of another type (a
    string parameter given what ROS reads as a float) for a node and for the container."""
    scene = () if message == "parameter 'scene'" else (
        "-p", f"scene:={REPO_ROOT / 'scenes' / 'thesis_lqg.yaml'}")
    proc = subprocess.run([sys.executable, "-m", f"{package}.node", "--ros-args", *scene, *args],
                          env=child_env(), cwd=REPO_ROOT, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2
    errors = [line for line in proc.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and message in errors[0] and "Traceback" not in proc.stderr


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_sim_waiting_for_its_peers_stops_cleanly(ros_domain: int, tmp_path: Path,
                                                 sig: int) -> None:
    result = tmp_path / "result.json"
    sim = start_node("sim_node", params_file(tmp_path, "thesis_lqg", [],
                                             result_file=str(result)))
    wait_for_log(sim, "waiting for the estimator")
    code, err = stop(sim, sig)
    assert code == 0 and "Traceback" not in err
    assert not result.exists()
