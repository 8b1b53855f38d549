"""The workstation launch: ``ros_ws/launch/closed_loop.launch.py`` and its parameter file."""

from __future__ import annotations

import ast
import configparser
import importlib.util
import py_compile
from pathlib import Path

import pytest

from stillframe.app.launcher import NODES
from stillframe.config.scene import load_scene
from stillframe.locations import REPO_ROOT
from stillframe.middleware.params import load_param_file

ROOT = REPO_ROOT
LAUNCH = ROOT / "ros_ws" / "launch" / "closed_loop.launch.py"
PARAMS = ROOT / "ros_ws" / "config" / "closed_loop.params.yaml"


@pytest.mark.parametrize("node", NODES)
def test_params_file_gives_each_node_its_parameters(node: str) -> None:
    """Read through the same loader the nodes use (rcl's node-key matching): every node gets
    the scene and the mode, only sim_node the result file."""
    params = load_param_file(PARAMS, f"/frame/{node}")
    shared = {"scene": "scenes/thesis_lqg.yaml", "mode": "lockstep"}
    if node == "sim_node":
        assert params == {**shared, "result_file": "closed_loop_result.json"}
    else:
        assert params == shared
    load_scene(ROOT / params["scene"])  # the scene named is a valid scene


def test_launch_file_compiles_and_starts_the_three_console_scripts(tmp_path: Path) -> None:
    """``launch_ros`` cannot be installed here (it comes only with a ROS 2 distribution, not
    from PyPI or Debian), so the file is compiled and its Node actions read from the syntax
    tree: package and executable are each node's console script (setup.cfg)."""
    py_compile.compile(str(LAUNCH), cfile=str(tmp_path / "launch.pyc"), doraise=True)
    tree = ast.parse(LAUNCH.read_text())
    nodes_tuple = next(node.value for node in ast.walk(tree) if isinstance(node, ast.Assign)
                       and any(getattr(t, "id", "") == "NODES" for t in node.targets))
    assert ast.literal_eval(nodes_tuple) == NODES
    call = next(node for node in ast.walk(tree) if isinstance(node, ast.Call)
                and getattr(node.func, "id", "") == "Node")
    keywords = {k.arg: k.value for k in call.keywords}
    assert all(getattr(keywords[k], "id", "") == "name"
               for k in ("package", "executable", "name"))
    assert "parameters" in keywords
    for name in NODES:
        cfg = configparser.ConfigParser()
        cfg.read(ROOT / name / "setup.cfg")
        assert cfg["options.entry_points"]["console_scripts"].split()[0] == name
    assert (LAUNCH.parent.parent / "config" / PARAMS.name).is_file()


@pytest.mark.skipif(importlib.util.find_spec("launch_ros") is None,
                    reason="launch_ros comes only with a ROS 2 distribution (not on PyPI/Debian)")
def test_launch_description_builds() -> None:
    spec = importlib.util.spec_from_file_location("closed_loop_launch", LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    assert len(description.entities) == 2 + len(NODES)
