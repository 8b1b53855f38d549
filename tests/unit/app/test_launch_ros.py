"""The workstation launch: ``ros_ws/launch/closed_loop.launch.py`` and its parameter file."""

from __future__ import annotations

import ast
import configparser
import json
import py_compile
import subprocess
from pathlib import Path

import pytest

from stillframe.app.launcher import MANAGED, NODES
from stillframe.config.scene import load_scene
from stillframe.locations import REPO_ROOT
from stillframe.middleware.params import load_param_file
from tests.support.ros2_peer import peer_env, ros2_or_skip

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
    """The file compiled and read from its syntax tree (launch_ros is not importable here): its
    node names are the launch's, the managed ones are ``LifecycleNode`` actions, package and
    executable are each node's console script (setup.cfg), and every node gets a run token."""
    py_compile.compile(str(LAUNCH), cfile=str(tmp_path / "launch.pyc"), doraise=True)
    tree = ast.parse(LAUNCH.read_text())
    nodes_tuple = next(node.value for node in ast.walk(tree) if isinstance(node, ast.Assign)
                       and any(getattr(t, "id", "") == "NODES" for t in node.targets))
    assert ast.literal_eval(nodes_tuple) == NODES
    calls = {node.func.id: {k.arg: k.value for k in node.keywords} for node in ast.walk(tree)
             if isinstance(node, ast.Call) and getattr(node.func, "id", "") in (
                 "Node", "LifecycleNode")}
    for keywords in calls.values():
        assert len({ast.unparse(keywords[k]) for k in ("package", "executable", "name")}) == 1
        assert ast.unparse(keywords["namespace"]) == "'frame'" and "parameters" in keywords
    assert "run_token" in LAUNCH.read_text()
    for name in NODES:
        cfg = configparser.ConfigParser()
        cfg.read(ROOT / name / "setup.cfg")
        assert cfg["options.entry_points"]["console_scripts"].split()[0] == name
    assert (LAUNCH.parent.parent / "config" / PARAMS.name).is_file()


#: the launch description's actions, built in the peer's Python (launch_ros is importable there)
DESCRIBE = """
import importlib.util, json, sys
spec = importlib.util.spec_from_file_location("closed_loop_launch", sys.argv[1])
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
entities = module.generate_launch_description().entities
print(json.dumps([[type(e).__name__, getattr(e, "node_executable", "") or type(
    getattr(e, "event_handler", None)).__name__] for e in entities]))
"""


def test_launch_description_builds_with_the_real_launch_ros() -> None:
    """In the real Jazzy launch_ros (the peer, tests/support/ros2_peer.py): three arguments;
    sim_node with the handler of its exit; each managed node a ``LifecycleNode`` with the handler
    that activates it once configured, the configure request, and the handler of its exit."""
    python = ros2_or_skip().parent / "python"
    done = subprocess.run([str(python), "-c", DESCRIBE, str(LAUNCH)], env=peer_env(),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == [
        *[["DeclareLaunchArgument", "NoneType"]] * 3,
        ["Node", "sim_node"], ["RegisterEventHandler", "OnProcessExit"],
        *[entity for name in MANAGED for entity in (
            ["LifecycleNode", name], ["RegisterEventHandler", "OnStateTransition"],
            ["EmitEvent", "NoneType"], ["RegisterEventHandler", "OnProcessExit"])]]
