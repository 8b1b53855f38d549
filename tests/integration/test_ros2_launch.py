"""``ros2 launch ros_ws/launch/closed_loop.launch.py`` with the real ros2launch and launch_ros of
Jazzy (the peer, ``tests/support/ros2_peer.py``; skipped where it is not installed) from a
colcon-built workspace, as docs/launch.md runs it.

The launch ends by itself when the simulator has ended the scene, having brought the estimator
and the controller (``autostart:=false``) through ``configure`` and ``activate``; its lock-step run
equals the one-process loop (``run_closed_loop``, no middleware) to the last bit, with no
lock-step timeout (an estimator or controller left inactive would have cost one a sample). A run
that fails (a scene no node can read) ends the launch with exit code 1, naming the code.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from tests.integration.test_colcon import install, sourced, workspace_env  # noqa: F401
from tests.integration.test_foreign_writers import HEARD_WITHIN, start_writer, stop_writer
from tests.support.nodes import SHORT_LQG
from tests.support.ros2_peer import PEER_ENV, ros2_or_skip
from tests.support.scenes import thesis_scene

pytestmark = pytest.mark.slow

LAUNCH = REPO_ROOT / "ros_ws" / "launch" / "closed_loop.launch.py"


def ros2_launch(install: Path, cwd: Path, *arguments: str,  # noqa: F811
                timeout: float = 300) -> subprocess.CompletedProcess:
    """``ros2 launch LAUNCH ARGUMENTS`` in a shell that sourced the workspace, the peer's
    ``ros2`` first on PATH (the nodes on this environment's backend, rclpy unless
    STILLFRAME_RMW says otherwise)."""
    ros2 = ros2_or_skip()
    env = {k: v for k, v in workspace_env().items() if k not in ("STILLFRAME_RMW", PEER_ENV)}
    quoted = " ".join(f"'{a}'" for a in arguments)
    return subprocess.run(sourced(install, f'PATH="{ros2.parent}:$PATH" exec ros2 launch '
                                           f'"{LAUNCH}" {quoted}'),
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture
def rclpy_nodes(ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The nodes on rclpy: the launch's lifecycle service calls are Fast DDS's."""
    pytest.importorskip("rclpy", reason="real rclpy is installed by `make setup` ([ros])")
    monkeypatch.delenv("STILLFRAME_RMW")


@pytest.mark.parametrize("beside", [False, True], ids=["alone", "beside_a_foreign_writer"])
def test_the_launch_brings_the_loop_up_and_ends_with_the_scene(
        install: Path, tmp_path: Path, rclpy_nodes: None, beside: bool) -> None:  # noqa: F811
    """Alone, and beside a foreign writer named ``controller_node`` in the root namespace,
    writing before the launch starts (the launch's run token keeps it out: the same numbers).
    Beside the writer, the gate is tested only by a run in which the simulator heard it (as in
    ``test_foreign_writers``: whether the simulator's graph found a foreign participant within a
    run of well under a second is discovery's timing); runs are repeated, at most
    :data:`HEARD_WITHIN`, until it did, and each is checked in full."""
    for attempt in range(HEARD_WITHIN if beside else 1):
        gate = check_ros2_launch(install, tmp_path / str(attempt), beside)
        if gate["rejected_foreign_writer"] or not beside:
            break
    assert (gate["rejected_foreign_writer"] > 0) == beside


def check_ros2_launch(install: Path, tmp_path: Path, beside: bool) -> dict:  # noqa: F811
    """One ``ros2 launch`` of the short LQG scene (beside the foreign writer): the lifecycle and
    the end in its log, the one-process loop's numbers to the last bit, the writer alone named
    where the simulator refused anything; the torque command's gate report."""
    tmp_path.mkdir()
    writer = start_writer("controller_node", "/", 500.0, None) if beside else None
    try:
        done = ros2_launch(install, tmp_path, f"overrides:={json.dumps(SHORT_LQG)}")
    finally:
        if writer is not None:
            stop_writer(writer)
    log = done.stdout + done.stderr
    assert done.returncode == 0, log[-4000:]
    for name in ("estimator_node", "controller_node"):
        assert f"[frame.{name}]: lifecycle: configure done" in log
        assert f"[frame.{name}]: lifecycle: activate done" in log
    assert "sim_node ended the scene: stopping the other nodes" in log
    assert "process has died" not in log, log[-4000:]
    result = json.loads((tmp_path / "closed_loop_result.json").read_text())
    assert result["complete"] is True
    reference = run_closed_loop(thesis_scene("thesis_lqg", SHORT_LQG))
    with np.load(tmp_path / "closed_loop_result.npz") as hist:
        np.testing.assert_array_equal(hist["command"], reference.command)
        np.testing.assert_array_equal(hist["truth"], reference.truth)
    gate = result["command_gates"]["pendulum/torque_cmd"]
    if gate["rejected_foreign_writer"]:
        assert gate["ignored_writers"] == "/controller_node", gate
        assert ("[frame.sim_node]: pendulum/torque_cmd: refusing the samples of a foreign "
                "writer (without the run's token): /controller_node") in log
    return gate


def test_a_failed_run_fails_the_launch(install: Path, tmp_path: Path,  # noqa: F811
                                       rclpy_nodes: None) -> None:
    done = ros2_launch(install, tmp_path, "scene:=/nonexistent/scene.yaml", timeout=120)
    log = done.stdout + done.stderr
    assert done.returncode == 1, log[-4000:]
    assert "sim_node: error: /nonexistent/scene.yaml: cannot read the scene file" in log
    assert "exited with code 2" in log and "the run failed" in log
