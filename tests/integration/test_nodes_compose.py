"""``launch --compose``: the estimator and the controller in one process (container_node) give
the one-process loop's numbers bit for bit, as the three processes do
(test_nodes_lockstep.py), and the estimates handed over in-process are still published on
``state_estimate`` for other listeners."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.launcher import CONTAINER, Launcher, LaunchOptions, run_scene
from stillframe.contract.topics import DEFAULT_NAMESPACE, STATE_ESTIMATE
from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from tests.support.nodes import SHORT_LQG
from tests.support.scenes import thesis_scene

SCENE = REPO_ROOT / "scenes" / "thesis_lqg.yaml"


def test_composed_run_equals_one_process(ros_domain: int, tmp_path: Path) -> None:
    stamps: list[int] = []

    def listen(node: Any) -> None:
        node.create_subscription(
            STATE_ESTIMATE.type_name, f"{DEFAULT_NAMESPACE}/{STATE_ESTIMATE.name}",
            lambda m: stamps.append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec),
            STATE_ESTIMATE.qos)

    result = run_scene(SCENE, SHORT_LQG, tmp_path, prepare=listen, backends=["dds"],
                       compose=True)
    reference = run_closed_loop(thesis_scene("thesis_lqg", SHORT_LQG))
    e = result.evaluation
    for key in ("reduction_pct", "peak_uncontrolled", "peak_controlled", "peak_command"):
        assert e[key] == reference.evaluation[key], key
    assert e["steps"] == reference.evaluation["steps"] == 192
    assert e["lockstep_timeouts"] == 0
    with np.load(result.history_file) as hist:
        for key in ("t", "truth", "command", "force", "fine_floors", "fine_velocities"):
            np.testing.assert_array_equal(hist[key], getattr(reference, key), err_msg=key)
    # published as well: the launcher's listener saw the estimates (the last ones may still be
    # in flight when sim_node ends the run)
    assert len(set(stamps)) >= 0.9 * e["steps"]
    assert any(name.endswith("controller_node") for name in result.diagnostics)


def test_compose_replaces_the_two_processes_by_the_container(ros_domain: int) -> None:
    launcher = Launcher(LaunchOptions(SCENE, list(SHORT_LQG), compose=True))
    try:
        commands = launcher.commands()
    finally:
        launcher.node.destroy_node()
    assert [name for name, _ in commands] == [CONTAINER, "sim_node"]
    assert dict(commands)[CONTAINER][1:3] == ["-m", "container_node.node"]
