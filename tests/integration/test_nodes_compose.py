"""``launch --compose`` / ``--compose-all``: the estimator and the controller (and the simulator)
in one process (container_node) give the one-process loop's numbers bit for bit, as the three
processes do (test_nodes_lockstep.py), and the samples handed over in-process are still published
for other listeners; the intra-process delivery hands each sample over once, with its writer's
GID, and another process still gets it through DDS."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from stillframe.app.launcher import CONTAINER, Launcher, LaunchOptions, run_scene
from stillframe.contract.topics import DEFAULT_NAMESPACE, FLOOR_IMU, STATE_ESTIMATE, TORQUE_CMD
from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from tests.support.middleware import finish, start_python, wait_for_line
from tests.support.nodes import SHORT_LQG, assert_same_histories
from tests.support.scenes import thesis_scene
from tests.support.waits import HANG_S

SCENE = REPO_ROOT / "scenes" / "thesis_lqg.yaml"


@pytest.mark.parametrize(("compose", "backend"), [("pair", "dds"), ("all", "dds"),
                                                  ("all", "rclpy")])
def test_composed_run_equals_one_process(ros_domain: int, tmp_path: Path, compose: str,
                                         backend: str) -> None:
    """On rclpy (no intra-process hand-over there) the composed nodes reach each other through
    Fast DDS, and the numbers are the same."""
    result = run_scene(SCENE, SHORT_LQG, out=tmp_path, record_dir=tmp_path / "bag",
                       backends=[backend], compose=compose)
    reference = run_closed_loop(thesis_scene("thesis_lqg", SHORT_LQG))
    e = result.evaluation
    for key in ("reduction_pct", "peak_uncontrolled", "peak_controlled", "peak_command"):
        assert e[key] == reference.evaluation[key], key
    assert e["steps"] == reference.evaluation["steps"] == 192
    assert e["complete"] is True
    with np.load(result.history_file) as hist:
        assert_same_histories(hist, reference)
    # published as well, for the recorder (which may join a few samples late, as in the demo)
    with AnyReader([tmp_path / "bag"]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    for topic in (FLOOR_IMU[0], STATE_ESTIMATE, TORQUE_CMD):
        assert 150 <= counts[f"{DEFAULT_NAMESPACE}/{topic.name}"] <= 192, topic.name
    statuses = {name.rsplit("/", 1)[-1]: values for name, values in result.diagnostics.items()}
    assert {"controller_node", "estimator_node", "sim_node"} <= set(statuses)
    # the last statuses, written as the nodes stopped, count the whole run
    assert statuses["controller_node"]["commands"] == "192"
    assert statuses["estimator_node"]["estimates"] == "192"


def test_compose_replaces_the_two_processes_by_the_container(ros_domain: int) -> None:
    launcher = Launcher(LaunchOptions(SCENE, list(SHORT_LQG), compose="pair"))
    try:
        commands = launcher.commands()
    finally:
        launcher.node.destroy_node()
    assert [name for name, _ in commands] == [CONTAINER, "sim_node"]
    assert dict(commands)[CONTAINER][1:3] == ["-m", "container_node"]


def test_compose_all_runs_every_node_in_the_container(ros_domain: int) -> None:
    launcher = Launcher(LaunchOptions(SCENE, list(SHORT_LQG), compose="all", rt="gc"))
    try:
        commands = dict(launcher.commands())
    finally:
        launcher.node.destroy_node()
    assert list(commands) == [CONTAINER]
    argv = commands[CONTAINER]
    assert argv[1:4] == ["-m", "container_node", "all"]
    # the simulator's parameters (result file, pinned command writer) and the practices
    assert any(a.startswith("result_file:=") for a in argv)
    assert "command_writer:=controller_node" in argv and "rt:=gc" in argv


#: two nodes of one process with intra-process delivery, and a node in a second process: the
#: in-process subscription gets each sample once (not again through DDS), with the writer's GID.
#: The writer keeps all 50 samples (reliable, depth 100, as the listener), so a listener that a
#: loaded machine runs late still gets every one: with the default depth of 10 it would not
INTRA = f"""
import sys, time
from stillframe.middleware import api, intra_process
from stillframe.middleware.qos import QoSProfile
intra_process.enable()
writer = api.create_node("intra_writer", backend="dds")
reader = api.create_node("intra_reader", backend="dds")
pub = writer.create_publisher("std_msgs/msg/Int32", "/intra_test", QoSProfile(depth=100))
got = []
sub = reader.create_subscription("std_msgs/msg/Int32", "/intra_test",
                                 lambda cdr, info: got.append((bytes(cdr), info.publisher_gid)),
                                 "default", raw=True)
deadline = time.monotonic() + {HANG_S}
while pub.get_subscription_count() < 2 and time.monotonic() < deadline:   # + the other process
    writer.spin_once(0.05)
print("counts", pub.get_subscription_count(), sub.get_publisher_count(), flush=True)
for i in range(50):
    pub.publish(bytes([0, 1, 0, 0]) + i.to_bytes(4, "little"))
deadline = time.monotonic() + {HANG_S}    # each sample arrives: waited for, not timed
while len(got) < 50 and time.monotonic() < deadline:
    reader.spin_once(0.05)
for _ in range(5):      # a second delivery (through DDS too) would show here
    reader.spin_once(0.05)
values = [int.from_bytes(cdr[4:8], "little") for cdr, _ in got]
print("got", len(got), values == list(range(50)), all(g == pub.gid for _, g in got), flush=True)
# the other process has every sample before this one exits
print("acked", pub.wait_for_all_acked({HANG_S}), flush=True)
"""

LISTENER = """
from stillframe.middleware import api
from stillframe.middleware.qos import QoSProfile
node = api.create_node("intra_listener", backend="dds")
seen = []
node.create_subscription("std_msgs/msg/Int32", "/intra_test",
                         lambda cdr, info: seen.append(cdr), QoSProfile(depth=100), raw=True)
print("ready", flush=True)
while len(seen) < 50 and api.ok():
    node.spin_once(0.1)
print("listener", len(seen), flush=True)
"""


def test_intra_process_hands_each_sample_over_once_and_still_publishes(ros_domain: int) -> None:
    listener = start_python(LISTENER)
    try:
        wait_for_line(listener, "ready")
        out, err = finish(start_python(INTRA), timeout=90)
        assert "counts 2 1" in out, err[-2000:]
        assert "got 50 True True" in out, err[-2000:]
        assert "acked True" in out, err[-2000:]
        out, err = finish(listener)
        assert "listener 50" in out, err[-2000:]
    finally:
        listener.kill()
