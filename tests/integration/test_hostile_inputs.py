"""Hostile inputs (issue 11, item 5) during a lock-step LQG run through the three nodes:

- a real rclpy node sends NaN, ±Inf, 1e308, stamps of zero, negative and far in the future, and a
  1 MB ``frame_id`` on the topics this loop does not use (``floor3/force_cmd``,
  ``floor3/load_cell``: LQG drives the pendulum torque): the sim refuses them by reason
  (``inactive_actuator``), the estimator ignores them;
- a 10 kHz flood from a real rclpy peer and a Cyclone writer on topics the loop does not read,
  on its own sensor topics, and on its control path and time (``state_estimate``, ``/clock``,
  ``pendulum/torque_cmd``): every node that reads a flooded topic refuses the samples by writer
  (or, for the inactive actuator, by reason) and counts them;

and the run equals the undisturbed one-process loop to the last bit. Truncated and garbage CDR
are dropped and counted by the delivery path every subscription uses (``malformed_samples`` in
each node's ``/diagnostics``).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from stillframe.contract import messages, topics
from stillframe.locations import REPO_ROOT
from stillframe.loop import writer_gate
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.middleware import api
from stillframe.middleware.api import create_node, spin_until
from tests.support.middleware import child_env, finish, wait_for_line
from tests.support.nodes import (
    SHORT_LQG,
    Statuses,
    params_file,
    run_loop_beside,
    start_node,
    stop,
)
from tests.support.scenes import thesis_scene
from tests.support.waits import HANG_S

WRITER = REPO_ROOT / "tests" / "support" / "hostile_writer.py"

RCLPY_WRITER = """
import math, signal
import rclpy
from geometry_msgs.msg import WrenchStamped
rclpy.init()
node = rclpy.create_node("hostile_writer", namespace="/frame")
pubs = [node.create_publisher(WrenchStamped, t, 10) for t in ("floor3/force_cmd",
                                                               "floor3/load_cell")]
stop = []
signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
values = [math.nan, math.inf, -math.inf, 1e308, 0.5]
stamps = [(0, 0), (-5, 0), (2_000_000_000, 0), (1, 0)]
big = "x" * 1_000_000
sent = 0
print("ready", flush=True)
while not stop:
    for value in values:
        for sec, nsec in stamps:
            msg = WrenchStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
            msg.header.frame_id = big if sent % 4000 == 0 else ""
            msg.wrench.force.x = value
            for pub in pubs:
                pub.publish(msg)
                sent += 1
    rclpy.spin_once(node, timeout_sec=0.02)
print("sent", sent, flush=True)
"""


@pytest.mark.slow
def test_garbage_and_hostile_values_change_nothing(ros_domain: int, tmp_path: Path) -> None:
    result, hist, sent = run_loop_beside(tmp_path, RCLPY_WRITER, "thesis_lqg", SHORT_LQG,
                                         command_writer="controller_node",
                                         diagnostics_period_s=0.2)
    assert sent > 0
    reference = run_closed_loop(thesis_scene("thesis_lqg", SHORT_LQG))
    np.testing.assert_array_equal(hist["truth"], reference.truth)
    np.testing.assert_array_equal(hist["command"], reference.command)
    assert result["reduction_pct"] == reference.evaluation["reduction_pct"]
    force_gate = result["command_gates"]["floor3/force_cmd"]
    assert force_gate["rejected_inactive_actuator"] > 0
    torque_gate = result["command_gates"]["pendulum/torque_cmd"]
    assert torque_gate["writer"] == "/frame/controller_node"


@pytest.mark.parametrize("kind", [s.type_name for s in (
    topics.FLOOR_IMU[0], topics.PENDULUM_JOINT_STATES, topics.EXCITATION_WRENCH,
    topics.TORQUE_CMD, topics.STATE_ESTIMATE)])
def test_truncated_and_garbage_cdr_is_dropped_and_counted(kind: str) -> None:
    """What every subscription of both backends does with bytes that do not decode (Cyclone's
    own writer refuses to send such bytes, so they are fed to the delivery path directly)."""
    whole = messages.serialize(messages.new(kind))
    rng = np.random.default_rng(0)
    bad = [whole[: len(whole) // 2], b"", b"\x00\x01\x00\x00",
           b"\x00\x01\x00\x00" + rng.integers(0, 256, 48, dtype=np.uint8).tobytes()]
    got: list = []
    malformed: Counter[str] = Counter()
    for data in [*bad, whole]:
        api.deliver(got.append, data, kind, "/hostile", malformed)
    assert len(got) == 1 and malformed == {"/hostile": len(bad)}


@dataclass
class Flooded:
    """What a run under a flood gave: the sim's histories and result, the nodes' last
    ``/diagnostics`` values, the one-process reference."""

    truth: np.ndarray
    command: np.ndarray
    evaluation: dict
    estimator: dict[str, str]
    controller: dict[str, str]
    sim: dict[str, str]
    reference: object


def _flood_run(tmp_path: Path, topic_set: str, flood_s: float, duration: float) -> Flooded:
    """Lock-step LQG for ``duration`` s of sim time through the three nodes while a real rclpy
    peer and a Cyclone writer of ours each send 5 kHz of hostile samples on ``topic_set``
    (``own``, ``unused`` or ``control``, ``tests/support/hostile_writer.py``) for ``flood_s`` s
    of wall time from the loop's t = 3 s on. The loop's writers are pinned by name, as ``stillframe
    launch`` pins them; with ``control`` the controller follows ``/clock`` (``use_sim_time``).
    Fails on any crash (a node not exiting 0)."""
    overrides = [f"duration={duration:g}", "controller.start=3", "evaluation.window=2"]
    result = tmp_path / "result.json"
    params = params_file(tmp_path, "thesis_lqg", overrides, result_file=str(result),
                         command_writer="controller_node", sensor_writer="sim_node",
                         estimate_writer="estimator_node", diagnostics_period_s=0.2)
    sim_time = ["-p", "use_sim_time:=true"] if topic_set == "control" else []
    peers = [start_node("estimator_node", params),
             start_node("controller_node", params, *sim_time)]

    def start_writers() -> list:
        return [subprocess.Popen([sys.executable, str(WRITER), backend, "5000", f"{flood_s:g}",
                                  topic_set, "3"], env=child_env(), cwd=REPO_ROOT,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                for backend in ("rclpy", "dds")]

    # the writers start before the sim and flood from the moment the loop reaches 3 s (when the
    # control starts: a stray sample taken would show in the commands), so that
    # a run shorter than a writer's start-up is flooded too
    writers = start_writers()
    sim = start_node("sim_node", params)
    watch = create_node("hostile_probe", argv=["test"])
    statuses = Statuses(watch)

    def loop_time() -> float:       # the sim's newest status (/clock itself may be flooded)
        return float(statuses.latest.get("/frame/sim_node", (0, "", {}))[2].get("sim_time_s", 0))

    try:
        assert all(wait_for_line(w, "ready") for w in writers)
        assert spin_until(watch, lambda: all(w.poll() is not None for w in writers), HANG_S)
        flooded = loop_time() - 3.0                 # the writers started at the loop's 3 s
        assert spin_until(watch, lambda: sim.poll() is not None, HANG_S)
        spin_until(watch, lambda: False, 0.5)
    finally:
        # the last line (Fast DDS logs its errors on stdout too)
        sent = [finish(w, timeout=120)[0].splitlines()[-1].split() for w in writers]
        watch.destroy_node()
        codes = [stop(p) for p in peers]
        if sim.poll() is None:
            stop(sim)
    assert sim.returncode == 0 and all(code == 0 for code, _ in codes)   # 0 crashes
    (_, *rclpy_counts, rclpy_rate), (_, *dds_counts, dds_rate) = sent
    print(f"flood on {topic_set} topics, {flood_s:g} s of wall time ({flooded:.2f} s of "
          f"the loop's time): rclpy {rclpy_rate} msg/s, {rclpy_counts[0]} samples, garbage sent "
          f"{rclpy_counts[1]}; dds {dds_rate} msg/s, {dds_counts[0]} samples, garbage refused by "
          f"Cyclone {dds_counts[2]}")
    assert int(rclpy_counts[1]) > 0                 # garbage CDR put on the wire by rclpy
    assert int(rclpy_counts[0]) > 0 and int(dds_counts[0]) > 0
    assert flooded > 0                              # the loop ran during the flood
    with np.load(result.with_suffix(".npz")) as data:
        truth, command = data["truth"], data["command"]
    est, ctl, sim_status = (statuses.latest[f"/frame/{n}"][2]
                            for n in ("estimator_node", "controller_node", "sim_node"))
    evaluation = json.loads(result.read_text())
    gate = evaluation["command_gates"]["floor3/force_cmd"]
    print("complete", evaluation["complete"], "estimator:",
          {k: est[k] for k in ("negative_stamps", "future_stamps",
                                             "stale_messages", "time_jumps", "partial_updates",
                                             "malformed_samples")},
          "controller: rejected_force_stamps", ctl["rejected_force_stamps"],
          "sim, floor3/force_cmd:", {k: v for k, v in gate.items() if k.startswith("rejected")
                                     and v},
          "refused by writer:", {n: {k: v for k, v in values.items()
                                     if "_rejected_" in k and "_writer" in k and v != "0"}
                                 for n, values in (("estimator", est), ("controller", ctl),
                                                   ("sim", sim_status))})
    return Flooded(truth, command, evaluation, est, ctl, sim_status,
                   run_closed_loop(thesis_scene("thesis_lqg", overrides)))


def refused(values: dict[str, str], topic: str, reasons: tuple[str, ...]) -> int:
    """A node's ``/diagnostics`` count of samples on ``topic`` refused for ``reasons``."""
    key = topic.strip("/").replace("/", "_")
    return sum(int(values[f"{key}_rejected_{r}"]) for r in reasons)


#: per flooded topic set: (node, topic, reasons) that must have refused samples
REFUSED = {
    "unused": [("sim", "floor3/force_cmd", ("inactive_actuator",))],
    "own": [("estimator", topic, writer_gate.REASONS)
            for topic in ("floor1/imu", "pendulum/joint_states", "excitation/wrench")]
    + [("controller", "excitation/wrench", writer_gate.REASONS)],
    "control": [("controller", "state_estimate", writer_gate.REASONS),
                ("controller", "/clock", writer_gate.REASONS),
                ("sim", "pendulum/torque_cmd", writer_gate.REASONS),
                ("estimator", "pendulum/torque_cmd", writer_gate.REASONS)],
}


def _refused_flood(tmp_path: Path, topic_set: str, flood_s: float, duration: float) -> None:
    """The flood changes nothing: the run equals the one-process loop to the last bit without
    a lock-step timeout, each node that reads a flooded topic refused samples (by writer, or
    the sim an inactive actuator's), and no stray stamp reached the estimator's checks."""
    got = _flood_run(tmp_path, topic_set, flood_s, duration)
    np.testing.assert_array_equal(got.truth, got.reference.truth)
    np.testing.assert_array_equal(got.command, got.reference.command)
    assert got.evaluation["complete"] is True
    nodes = {"estimator": got.estimator, "controller": got.controller, "sim": got.sim}
    for node, topic, reasons in REFUSED[topic_set]:
        assert refused(nodes[node], topic, reasons) > 0, (node, topic)
    for key in ("negative_stamps", "future_stamps", "stale_messages", "time_jumps",
                "partial_updates"):
        assert got.estimator[key] == "0", key
    assert got.controller["rejected_force_stamps"] == "0"


@pytest.mark.slow
@pytest.mark.parametrize("topic_set", REFUSED)
def test_flood_is_refused_by_writer_and_changes_nothing(ros_domain: int, tmp_path: Path,
                                                        topic_set: str) -> None:
    """10 kHz of hostile samples for 2 s (stamps 0, -5 s, +2e9 s; 1 MB and empty frame_id;
    JointState arrays of mismatched lengths; garbage and truncated CDR on the wire from rclpy),
    from a real rclpy peer and a Cyclone writer, from the loop's t = 3 s on (when the control
    starts), on topics the loop does not read (``floor3/force_cmd``, ``floor3/load_cell``,
    ``unused/imu``), on its own sensor topics (``floor1/imu``, ``pendulum/joint_states``,
    ``excitation/wrench``), or on its control path and time (``state_estimate``, ``/clock``,
    ``pendulum/torque_cmd``, also stamped with the loop's own ``/clock``): no crash, each node
    that reads a flooded topic refuses and counts the samples, the run equals the one-process
    loop to the last bit."""
    _refused_flood(tmp_path, topic_set, 2.0, 8.0)


@pytest.mark.long
def test_flood_on_the_loops_own_sensor_topics_for_ten_seconds(ros_domain: int,
                                                              tmp_path: Path) -> None:
    """As above on the loop's own sensor topics, 10 kHz for 10 s."""
    _refused_flood(tmp_path, "own", 10.0, 30.0)


@pytest.mark.slow
def test_garbage_cdr_on_the_wire_is_dropped_and_counted(ros_domain: int) -> None:
    """A real rclpy peer puts garbage and truncated CDR on the wire under the right type names
    (rclpy publishes bytes as they are; Cyclone's writer refuses them): a reader on the rclpy
    backend drops and counts them (``malformed_samples``) and reads the rest; a reader on the
    ``dds`` backend reads the rest too, and counts the garbage Cyclone drops before our code
    sees it (from Cyclone's "deserialization ... failed" lines, issue 31)."""
    readers = {backend: subprocess.Popen(
        [sys.executable, str(REPO_ROOT / "tests" / "support" / "counting_reader.py"), backend],
        env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True) for backend in ("rclpy", "dds")}
    assert all(wait_for_line(r, "ready") for r in readers.values())
    writer = subprocess.Popen([sys.executable, str(WRITER), "rclpy", "2000", "2", "own", "0",
                               str(len(readers))],
                              env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    out, err = finish(writer, timeout=60)
    assert writer.returncode == 0, err[-2000:]
    garbage_sent = int(out.split()[-3])
    read = {}
    time.sleep(1.0)                                              # what is in flight
    for backend, r in readers.items():
        r.send_signal(signal.SIGTERM)
        r_out, r_err = finish(r)
        assert r.returncode == 0, r_err[-2000:]                  # no crash
        read[backend] = [int(v) for v in r_out.split()[-2:]]
    print(f"garbage sent by rclpy {garbage_sent}; read (good, malformed): {read}")
    assert garbage_sent > 0
    assert read["rclpy"][0] > 0 and read["rclpy"][1] > 0
    assert read["dds"][0] > 0 and 0 < read["dds"][1] <= garbage_sent


def test_cyclones_deserialisation_failures_are_counted_and_passed_on() -> None:
    """The stderr tap (``middleware/cyclone_log.py``) in a real process: Cyclone's lines for
    refused samples (as its receive thread writes them, straight to file descriptor 2) are
    counted under their ROS topic, and every byte still reaches the real stderr."""
    line = ("1795606091.187346 [226]       recv: data(application, vendor 1.15): "
            "10f78fd:4f614cfd:0:1503 #70: deserialization rt/frame/{topic}/{type} failed "
            "(for reasons unknown)\n")
    script = (
        "import os, sys\n"
        "from stillframe.middleware import api\n"
        "from stillframe.middleware.cyclone_log import count_deserialization_failures\n"
        "count_deserialization_failures()\n"
        "for t, ty in [('excitation/wrench', 'geometry_msgs::msg::dds_::WrenchStamped_'),\n"
        "              ('floor1/imu', 'sensor_msgs::msg::dds_::Imu_')] * 3:\n"
        f"    os.write(2, {line!r}.format(topic=t, type=ty).encode())\n"
        "os.write(2, b'other output\\n')\n"
        "import time\n"
        "deadline = time.monotonic() + 60    # the tap's thread has counted them all\n"
        "while sum(api.CYCLONE_DROPPED.values()) < 6 and time.monotonic() < deadline:\n"
        "    time.sleep(0.01)\n"
        "print(dict(api.CYCLONE_DROPPED), flush=True)\n")
    done = subprocess.run([sys.executable, "-c", script], env=child_env(), cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "{'/frame/excitation/wrench': 3, '/frame/floor1/imu': 3}"
    assert done.stderr.count("deserialization rt/frame/") == 6
    assert done.stderr.endswith("other output\n")
