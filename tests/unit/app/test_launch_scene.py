"""``launch`` parses and resolves the scene once and hands the nodes the result: every node's
command names the resolved scene file and no overrides; the file loads back to the very scene
the launcher resolved (the same floats), and the managed nodes start
with ``autostart`` false."""

from __future__ import annotations

from pathlib import Path

import pytest

from stillframe.app import launcher
from stillframe.config.scene import load_scene
from stillframe.fidelity.auto_model import resolve_model
from stillframe.middleware.params import node_overrides, parse_ros_args
from tests.support.nodes import SCENES

OVERRIDES = ["duration=2", "controller.start=1", "evaluation.window=0.5",
             "plant.process_noise_std=[1e-7, 0, 0, 0, 0, 0, 0, 0.1]"]


@pytest.mark.processes
def test_nodes_get_the_resolved_scene(ros_domain: int, tmp_path: Path,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[object] = []

    def counted(scene: object) -> object:
        calls.append(scene)
        return resolve_model(scene)   # type: ignore[arg-type]

    monkeypatch.setattr(launcher, "resolve_model", counted)
    scene_file = SCENES / "thesis_lqg.yaml"
    run = launcher.Launcher(launcher.LaunchOptions(
        scene_file, OVERRIDES, result_file=tmp_path / "result.json"))
    try:
        run.write_scene()
        commands = dict(run.commands())
        run.nodes()
    finally:
        run.node.destroy_node()
    assert len(calls) == 1                  # resolved once, for every child
    resolved = tmp_path / launcher.RESOLVED_SCENE
    expected = resolve_model(load_scene(scene_file, OVERRIDES))[0]
    assert load_scene(resolved) == expected   # bit for bit: floats as repr writes them
    assert set(commands) == set(launcher.NODES)
    for name, argv in commands.items():
        params = node_overrides(parse_ros_args(argv[argv.index("--ros-args"):]), f"/{name}")
        assert params["scene"] == str(resolved) and "overrides" not in params
        assert params.get("autostart", True) is (name not in launcher.MANAGED)
    assert launcher.MANAGED == ("estimator_node", "controller_node")


@pytest.mark.processes
def test_a_given_resolved_scene_is_not_loaded_again(ros_domain: int, tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    scene = resolve_model(load_scene(SCENES / "thesis_lqg.yaml", OVERRIDES))[0]
    monkeypatch.setattr(launcher, "load_scene", lambda *_: pytest.fail("loaded again"))
    run = launcher.Launcher(launcher.LaunchOptions(
        Path("unused.yaml"), resolved=scene, result_file=tmp_path / "result.json"))
    try:
        assert launcher.nodes_for(run.scene) == list(launcher.NODES)
        run.write_scene()
    finally:
        run.node.destroy_node()
    assert load_scene(tmp_path / launcher.RESOLVED_SCENE) == scene
