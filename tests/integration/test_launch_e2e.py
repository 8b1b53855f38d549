"""``stillframe launch``, ``reproduce`` and ``demo`` through the real nodes over DDS, on shortened
scenes. The independent reference is ``stillframe closed-loop`` (one process, no middleware):
lock-step through three processes with the same scene and seeds must give the same numbers."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from stillframe.locations import REPO_ROOT
from tests.integration.test_launch_processes import alive, wait_for_children
from tests.support.middleware import child_env, finish, run_stillframe, start_python, wait_for_line

SCENES = REPO_ROOT / "scenes"
#: 6 s of the thesis's set-up: control from 3 s, peaks over 3 s windows
SHORT = ["--set", "duration=6", "--set", "controller.start=3", "--set", "evaluation.window=3"]

pytestmark = pytest.mark.slow


def one_process(scene: str, *overrides: str) -> dict:
    done = run_stillframe("closed-loop", str(SCENES / scene), *overrides, "--json", timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


# thesis_lqg's launch equals its one-process run by default in test_ros2_interop (rclpy)
@pytest.mark.parametrize("scene", [pytest.param("thesis_lqg.yaml", marks=pytest.mark.long),
                                   "thesis_euk_ekf.yaml"])
def test_launch_equals_one_process_run(scene: str, ros_domain: int) -> None:
    done = run_stillframe("launch", str(SCENES / scene), *SHORT, "--json", timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    nodes = json.loads(done.stdout)
    # the schema
    assert len(nodes["reduction_pct"]["displacement"]) == 3
    assert len(nodes["reduction_pct"]["velocity"]) == 3
    for key in ("peak_command", "steps", "wall_s"):
        assert isinstance(nodes[key], int | float), key
    assert nodes["complete"] is True
    # the managed nodes brought up by the launch (lifecycle), and active to the end
    for name in ("estimator_node", "controller_node"):
        assert f"{name}: configured and active" in done.stderr
        assert nodes["diagnostics"][f"/frame/{name}"]["lifecycle"] == "active"
    reference = one_process(scene, *SHORT)
    assert nodes["steps"] == reference["steps"] == 6 * 32
    # on a mismatch, show what the nodes counted (lost samples, partial updates, timeouts)
    counters = {"sim": {k: nodes.get(k) for k in ("complete", "rejected_commands")},
                **nodes["diagnostics"]}
    for quantity in ("displacement", "velocity"):
        assert nodes["reduction_pct"][quantity] == pytest.approx(
            reference["reduction_pct"][quantity], abs=1e-9), counters
        assert nodes["peak_uncontrolled"][quantity] == pytest.approx(
            reference["peak_uncontrolled"][quantity], rel=1e-12)
    assert nodes["peak_command"] == pytest.approx(reference["peak_command"], rel=1e-9)


def start_launch(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "stillframe", "launch", str(SCENES / "thesis_lqg.yaml"), *args],
        env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)


def test_killed_real_node_is_named(ros_domain: int) -> None:
    proc = start_launch()
    pids, _ = wait_for_children(proc, timeout=120)
    os.kill(pids["estimator_node"], signal.SIGKILL)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 1, err[-3000:]
    assert "stillframe launch: error: estimator_node died (killed by SIGKILL)" in err
    assert not any(alive(pid) for pid in pids.values())


def test_a_dying_node_leaves_a_partial_result_the_statuses_and_a_closed_bag(
        tmp_path: Path, ros_domain: int) -> None:
    """Issue 31 (3): the controller is SIGKILLed once the simulator has run samples (a status
    line says so; the scene is long enough never to end first). The launcher names it, stops
    the others with SIGINT, and keeps what the run has: the simulator's samples so far (in the
    result and the histories), the nodes' statuses and the bag, closed; exit 1."""
    out = tmp_path / "out"
    proc = start_launch("--set", "duration=600", "--record", str(tmp_path / "bag"),
                        "--out", str(out), "--json")
    pids, lines = wait_for_children(proc, count=4, timeout=120)
    while not any(int(m.group(1)) > 0 for line in lines
                  if (m := re.search(r"sim_node: .*\bstep=(\d+)", line))):
        line = proc.stderr.readline()
        assert line, f"no status line with a step: {lines[-20:]}"
        lines.append(line)
    os.kill(pids["controller_node"], signal.SIGKILL)
    stdout, err = proc.communicate(timeout=120)
    assert proc.returncode == 1, err[-3000:]
    assert "stillframe launch: error: controller_node died (killed by SIGKILL)" in err
    assert not any(alive(pid) for pid in pids.values())
    partial = json.loads(stdout)
    assert partial["complete"] is False
    assert partial["died"] == {"node": "controller_node", "how": "killed by SIGKILL"}
    assert partial["stopped"] == {"recorder": "exit code 0", "sim_node": "exit code 0",
                                  "estimator_node": "exit code 0"}
    assert 0 < partial["steps"] < partial["steps_planned"] == 600 * 32
    assert "/frame/sim_node" in partial["diagnostics"]
    assert json.loads((out / "result.json").read_text()) == {
        k: v for k, v in partial.items() if k != "scene"}
    with np.load(out / "result.npz") as histories:
        assert histories["t"].shape == (partial["steps"],)
    assert partial["bag"]["closed"] is True
    with AnyReader([tmp_path / "bag"]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert sum(counts.values()) == partial["bag"]["messages"]
    # the recorder has the simulator's samples up to its last one, not beyond
    assert 0 < counts["/frame/floor1/imu"] <= partial["steps"] + 1


def test_ctrl_c_stops_the_real_nodes_and_the_recorder(tmp_path: Path,
                                                      ros_domain: int) -> None:
    """The recorder closes its bag on the forwarded SIGINT: the partial bag is readable."""
    proc = start_launch("--record", str(tmp_path / "bag"))
    pids, lines = wait_for_children(proc, count=4, timeout=120)
    # Ctrl-C only once the recorder has discovered the sensor topic (discovery takes a moment)
    wanted = "Subscribed to topic '/frame/floor1/imu'"
    while not any(wanted in line for line in lines):
        line = proc.stderr.readline()
        assert line, f"the recorder never subscribed to the IMU topic: {lines[-20:]}"
        lines.append(line)
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, "".join(lines[-30:]) + err[-3000:]
    assert not any(alive(pid) for pid in pids.values())
    with AnyReader([tmp_path / "bag"]) as reader:
        assert {c.topic for c in reader.connections} >= {"/frame/floor1/imu", "/clock"}


@pytest.mark.long      # every shipped thesis scene in turn; the demo test runs one by default
def test_reproduce_prints_each_scene_beside_the_thesis(ros_domain: int) -> None:
    scenes = [str(SCENES / "thesis_lqg.yaml"), str(SCENES / "thesis_euk_ekf.yaml")]
    done = run_stillframe("reproduce", *scenes, *SHORT, "--json", timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    document = json.loads(done.stdout)
    assert [s["scene"] for s in document["scenes"]] == ["thesis_lqg", "thesis_euk_ekf"]
    for entry, scene in zip(document["scenes"], ["thesis_lqg.yaml", "thesis_euk_ekf.yaml"],
                            strict=True):
        reference = one_process(scene, *SHORT)
        assert entry["reduction_pct"]["displacement"] == pytest.approx(
            reference["reduction_pct"]["displacement"], abs=1e-9)
    lqg = document["scenes"][0]
    assert lqg["reference_pct"] == {"displacement": [71.09, 74.95, 56.94],
                                    "velocity": [73.59, 80.49, 70.48]}
    targets = {t["target"]: t["met"] for t in document["targets"]}
    lqg_ok = min(lqg["reduction_pct"]["displacement"]) >= 50
    assert targets["thesis_lqg: displacement reduction >= 50 % on every floor"] == lqg_ok
    euk = document["scenes"][1]["reduction_pct"]["displacement"][2]
    assert targets["thesis_euk_ekf: displacement reduction >= 85 % on floor 3"] == (euk >= 85)
    # the text form has one table per scene with the thesis's column
    text = run_stillframe("reproduce", scenes[0], *SHORT, timeout=600)
    assert text.returncode == 0
    assert "71.09" in text.stdout and "thesis %" in text.stdout


#: another loop's simulator on the shell's domain (what made ``launch`` refuse to start there)
OTHER_LOOP = """
from stillframe.middleware.api import create_node, spin
node = create_node("sim_node", namespace="/frame", argv=["other"])
print("ready", flush=True)
spin(node)
node.destroy_node()
"""


def test_demo_writes_a_bag_and_a_plot(tmp_path: Path, ros_domain: int) -> None:
    """Beside another loop on the shell's domain (a launch there refuses to start): the demo
    runs isolated on a domain of its own and says so in one line."""
    other = start_python(OTHER_LOOP)
    wait_for_line(other, "ready")
    out = tmp_path / "demo"
    try:
        beside = run_stillframe("launch", "thesis_lqg", *SHORT, timeout=120)
        done = run_stillframe("demo", "--out", str(out), *SHORT, timeout=600)
    finally:
        other.terminate()
        finish(other)
    assert beside.returncode == 2 and "another stillframe loop is running" in beside.stderr
    assert done.returncode == 0, done.stderr[-3000:]
    isolated = [line for line in done.stderr.splitlines() if line.startswith("demo: isolated")]
    assert len(isolated) == 1, done.stderr[-3000:]
    domain = int(isolated[0].split("ROS_DOMAIN_ID=")[1].split(",")[0])
    assert domain != ros_domain and 1 <= domain <= 232
    assert "71.09" in done.stdout  # the thesis's column beside ours
    png = (out / "floors.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    with AnyReader([out / "bag"]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    # 6 s at 32 Hz: the recorder may join a few samples late, never more than it was sent
    assert 150 <= counts["/frame/floor1/imu"] <= 192
    assert counts["/frame/pendulum/torque_cmd"] >= 150
    result = json.loads((out / "result.json").read_text())
    assert result["steps"] == 192
