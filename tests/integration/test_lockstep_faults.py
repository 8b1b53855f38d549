"""Lock-step is bit-identical or fails loudly (docs/nodes.md, lock-step protocol).

- The controller, or the estimator, stopped (SIGSTOP) for 3 s in the middle of a lock-step run
  and continued: the simulator waits (its clock stands still meanwhile: the condition is
  forced, whatever the machine's speed), and the run equals the one-process loop to the last
  bit. The EKF + EUK scene with the estimator stopped is the case that diverged when lock-step
  held a command after a timeout: with the estimator stopped 2.5 s at t = 22 s of a 40 s run,
  the three-process loop gave reductions of 1.0 / 1.3 / 0.4 % against the one-process
  86.4 / 90.0 / 95.7 % (two held commands).
- The controller killed (SIGKILL) under ``stillframe launch``: the launch ends at once with one
  line naming it and exit code 1, the samples run so far kept (``"complete": false``).
- The controller killed beside the nodes run by hand (no launcher to notice): the simulator ends
  the run once the graph drops the dead peer (its DDS lease: 10 s on Cyclone), with one line
  naming the peer and the sample, exit code 7 and the partial result.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from stillframe.contract import messages, topics
from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.middleware.api import create_node, spin_until
from tests.support.middleware import child_env, finish
from tests.support.nodes import assert_same_histories, params_file, start_node, stop
from tests.support.scenes import thesis_scene

SCENE = "thesis_lqg"
#: 120 s of sim time (3840 samples), control from 10 s: the probe acts at 12 s, with control
#: on, and the run cannot have ended by then (it is 108 s of lock-step away)
OVERRIDES = ["duration=120", "controller.start=10", "evaluation.window=10"]
#: the killed-peer runs: long enough that no machine ends them before the kill
KILLED = ["duration=600", "controller.start=10", "evaluation.window=10"]
ACT_AT_S = 12.0
PERIOD_NS = round(1e9 / 32)
STOPPED_S = 3.0


class Clock:
    """The test's node: the newest ``/clock`` the simulator published."""

    def __init__(self) -> None:
        self.node = create_node("lockstep_fault_probe", argv=["test"])
        self.ns = 0
        self.node.create_subscription(topics.CLOCK.type_name, "/clock", self.on_clock, "clock")

    def on_clock(self, msg: object) -> None:
        self.ns = messages.stamp_ns(msg.clock)

    def until(self, seconds: float, timeout: float = 120) -> None:
        assert spin_until(self.node, lambda: self.ns >= seconds * 1e9, timeout)

    def wait(self, seconds: float) -> None:
        spin_until(self.node, lambda: False, seconds)


@pytest.mark.slow
@pytest.mark.parametrize(("victim", "scene"), [("controller_node", "thesis_lqg"),
                                               ("estimator_node", "thesis_euk_ekf")])
def test_a_peer_stopped_for_3_s_changes_no_bit(ros_domain: int, tmp_path: Path,
                                               victim: str, scene: str) -> None:
    result = tmp_path / "result.json"
    params = params_file(tmp_path, scene, OVERRIDES, result_file=str(result))
    peers = {name: start_node(name, params) for name in ("estimator_node", "controller_node")}
    sim = start_node("sim_node", params)
    clock = Clock()
    try:
        clock.until(ACT_AT_S)
        peers[victim].send_signal(signal.SIGSTOP)
        clock.wait(0.2)                     # what was in flight when it stopped
        stopped_at = clock.ns
        clock.wait(STOPPED_S)
        held = clock.ns
        running = sim.poll() is None
        peers[victim].send_signal(signal.SIGCONT)
        _out, err = finish(sim, timeout=300)
    finally:
        clock.node.destroy_node()
        logs = {}
        for name, proc in (*peers.items(), ("sim_node", sim)):
            proc.send_signal(signal.SIGCONT)
            if proc.poll() is None:
                logs[name] = stop(proc)[1]
    print(f"{victim} stopped at sim time {stopped_at * 1e-9:.4f} s; "
          f"{STOPPED_S:g} s later {held * 1e-9:.4f} s")
    assert held == stopped_at and running   # the simulator waited for the stopped peer
    assert stopped_at < 110e9               # ... in the middle of the run, control on
    assert sim.returncode == 0, err[-2000:] + "".join(
        f"\n--- {name}:\n{text[-2000:]}" for name, text in logs.items())
    evaluation = json.loads(result.read_text())
    assert evaluation["complete"] is True
    reference = run_closed_loop(thesis_scene(scene, OVERRIDES))
    with np.load(result.with_suffix(".npz")) as data:
        assert_same_histories(data, reference)
    assert evaluation["reduction_pct"] == reference.evaluation["reduction_pct"]


@pytest.mark.slow
def test_a_killed_controller_ends_the_launch_at_once(ros_domain: int, tmp_path: Path) -> None:
    out = tmp_path / "out"
    launch = subprocess.Popen(
        [sys.executable, "-m", "stillframe", "launch", SCENE, *(f"--set={o}" for o in KILLED),
         "--out", str(out), "--json"],
        env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    clock = Clock()
    try:
        clock.until(ACT_AT_S)
        pid = _child_pid(launch.pid, "controller_node")
        subprocess.run(["kill", "-KILL", str(pid)], check=True)
        stdout, stderr = finish(launch, timeout=60)
    finally:
        clock.node.destroy_node()
        if launch.poll() is None:
            launch.kill()
    assert launch.returncode == 1, stderr[-3000:]
    errors = [line for line in stderr.splitlines() if line.startswith("stillframe launch: error")]
    assert errors == ["stillframe launch: error: controller_node died (killed by SIGKILL)"]
    partial = json.loads(stdout)
    assert partial["complete"] is False and partial["died"]["node"] == "controller_node"
    assert 0 < partial["steps"] < partial["steps_planned"]


@pytest.mark.slow
def test_a_killed_controller_ends_the_run_of_nodes_started_by_hand(
        ros_domain: int, tmp_path: Path) -> None:
    """On the suite's backend (dds: Cyclone, whose lease is 10 s) the graph drops the killed
    controller within its lease; the simulator then names it and the sample that waited."""
    result = tmp_path / "result.json"
    params = params_file(tmp_path, SCENE, KILLED, result_file=str(result))
    peers = {name: start_node(name, params) for name in ("estimator_node", "controller_node")}
    sim = start_node("sim_node", params)
    clock = Clock()
    try:
        clock.until(ACT_AT_S)
        peers["controller_node"].kill()
        _out, err = finish(sim, timeout=60)
    finally:
        clock.node.destroy_node()
        for proc in (*peers.values(), sim):
            if proc.poll() is None:
                stop(proc)
    assert sim.returncode == 7, err[-2000:]
    lines = [line for line in err.splitlines() if ": error: " in line]
    evaluation = json.loads(result.read_text())
    sample = evaluation["steps"]
    assert len(lines) == 1 and lines[0].endswith(
        f"error: lock-step: controller_node left the graph while sample {sample} "
        f"(t = {sample / 32:g} s) awaited its command; the run ended there"), err[-2000:]
    assert evaluation["complete"] is False and evaluation["error"]["kind"] == "LoopError"


def _child_pid(parent: int, name: str) -> int:
    """The pid of the launch's child running the node package ``name`` (``python -m name``)."""
    out = subprocess.run(["pgrep", "-P", str(parent), "-f", "--", f"-m {name}( |$)"],
                         capture_output=True, text=True, check=True).stdout.split()
    assert len(out) == 1, out
    return int(out[0])
