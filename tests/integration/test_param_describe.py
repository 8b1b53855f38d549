"""Parameters as a Jazzy user sees them (issue 39, items 1 and 4): ``stillframe param
describe|get|set|load`` and the real ``ros2 param describe`` against a node that declares the
controller's parameters as controller_node does, on each backend.

The independent sides: rclpy builds the rclpy-backend node's descriptors itself (from the
``ParameterDescriptor`` it is given) and the real ros2cli prints them, where it is installed
(``tests/support/ros2_peer.py``); the dds-backend node's descriptors must read the same.
"""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import pytest

from stillframe.middleware import api
from stillframe.node_runtime.declarations import NODE_PARAMETERS
from tests.support.middleware import finish, run_stillframe, start_python, wait_for_line
from tests.support.ros2_peer import run_ros2

BACKENDS = ["dds", pytest.param("rclpy", marks=pytest.mark.skipif(
    not api.has_rclpy(), reason="rclpy not installed"))]

#: a node declaring every parameter controller_node declares, as it declares them, with a
#: publisher as every loop node has (its vendor shows in the GUIDs of its topic endpoints)
CONTROLLER = """
import sys
from stillframe.middleware.api import create_node, spin
from stillframe.node_runtime.declarations import NODE_PARAMETERS
from stillframe.node_runtime.parameters import declare
scene = type("Scene", (), {"controller": type("C", (), {"limit": 0.5})()})()
node = create_node("controller_node", namespace="/frame",
                   argv=["peer", "--ros-args", "-p", "scene:=scenes/thesis_lqg.yaml"])
for cls in NODE_PARAMETERS["controller_node"]:
    declare(node, cls, scene)
node.create_publisher("diagnostic_msgs/msg/DiagnosticArray", "/diagnostics", 10)  # as a loop node
print("ready", flush=True)
spin(node)
node.destroy_node()
"""
NAMES = ("command_limit", "rt_priority", "mode", "diagnostics_period_s", "scene", "enabled")


def start_controller(backend: str, monkeypatch: pytest.MonkeyPatch) -> subprocess.Popen:
    monkeypatch.setenv("STILLFRAME_RMW", backend)
    proc = start_python(CONTROLLER)
    wait_for_line(proc, "ready", timeout=60)
    return proc


@pytest.fixture
def controller(ros_domain: int, request: pytest.FixtureRequest,
               monkeypatch: pytest.MonkeyPatch) -> str:
    """The declaring node on the backend of the test's parameter; the tools on the same."""
    proc = start_controller(request.param, monkeypatch)
    yield request.param
    proc.terminate()
    finish(proc)
    run_stillframe("daemon", "stop")


def one_error(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


def expected_lines(name: str) -> list[str]:
    """What ros2param's describe verb prints for the declaration of ``name`` (written here from
    ros2cli's Jazzy source: Type, Description, Constraints with Read only, Min/Max value and
    Additional constraints)."""
    spec = next(s for cls in NODE_PARAMETERS["controller_node"] for s in cls.specs()
                if s.name == name)
    described = spec.descriptor()
    kind = spec.type_text.replace("bool", "boolean").replace("[]", " array")
    lines = [f"Parameter name: {name}", f"  Type: {kind}",
             f"  Description: {described.description}", "  Constraints:"]
    if described.read_only:
        lines.append("    Read only: true")
    if described.range is not None:
        low, high = described.range.low, described.range.high
        if spec.kind is int:        # an infinite bound is int64's limit
            low, high = (int(b) if math.isfinite(b) else (2**63 - 1 if b > 0 else -(2**63))
                         for b in (low, high))
        else:
            low, high = float(low), float(high)
        lines += [f"    Min value: {low}", f"    Max value: {high}"]
    if described.additional_constraints:
        lines.append(f"    Additional constraints: {described.additional_constraints}")
    return lines


@pytest.mark.parametrize("controller", BACKENDS, indirect=True)
def test_param_describe_shows_the_declarations(controller: str) -> None:
    result = run_stillframe("param", "describe", "controller_node", *NAMES)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [line for n in NAMES for line in expected_lines(n)]
    described = json.loads(run_stillframe("param", "describe", "controller_node",
                                          "command_limit", "rt_priority", "--json").stdout)
    assert described[0]["range"] == {"from": 0.0, "to": None, "step": 0.0}
    assert described[1]["range"]["from"] >= 1 and described[1]["read_only"]
    assert not described[0]["read_only"]


@pytest.mark.parametrize("controller", ["rclpy"], indirect=True)
def test_the_real_ros2_param_describe_shows_the_declarations(controller: str) -> None:
    """ros2cli (Fast DDS, as the rclpy backend) prints what stillframe's verb prints."""
    result = run_ros2("param", "describe", "--no-daemon", "--timeout", "10",
                      "/frame/controller_node", *NAMES)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [line for n in NAMES for line in expected_lines(n)]


@pytest.mark.parametrize("controller", BACKENDS, indirect=True)
def test_an_unknown_name_is_one_line_naming_the_closest(controller: str) -> None:
    for verb in (["get"], ["set"], ["describe"]):
        args = ["param", *verb, "controller_node", "comand_limit", *(["1.0"] if verb == [
            "set"] else [])]
        line = one_error(run_stillframe(*args))
        assert line == ("stillframe param: error: node /frame/controller_node has no parameter "
                        "'comand_limit' (did you mean command_limit?)"), line
    line = one_error(run_stillframe("param", "get", "controller_node", "xyzzy"))
    assert "has no parameter 'xyzzy' (its parameters: autostart, command_limit," in line


@pytest.mark.parametrize("controller", BACKENDS, indirect=True)
def test_param_load_takes_the_bare_node_name_and_never_applies_nothing(
        controller: str, tmp_path: Path) -> None:
    """The README's form ``controller_node:`` is this node (ros2 param load takes it); a file
    none of whose keys names the node is refused with its keys, instead of setting nothing."""
    bare = tmp_path / "bare.yaml"
    bare.write_text("controller_node:\n  ros__parameters:\n    command_limit: 0.02\n"
                    "/**:\n  ros__parameters:\n    enabled: false\n")
    result = run_stillframe("param", "load", "controller_node", str(bare))
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["Set parameter enabled successful",
                                          "Set parameter command_limit successful"]
    got = run_stillframe("param", "get", "controller_node", "command_limit")
    assert got.stdout.strip() == "0.02"
    assert run_stillframe("param", "get", "controller_node", "enabled").stdout.strip() == "False"
    result = run_stillframe("param", "load", "controller_node", str(bare), "--no-use-wildcard")
    assert result.stdout.splitlines() == ["Set parameter command_limit successful"]
    other = tmp_path / "other.yaml"
    other.write_text("/frame/sim_node:\n  ros__parameters:\n    result_file: x.json\n")
    line = one_error(run_stillframe("param", "load", "controller_node", str(other)))
    assert line == (f"stillframe param: error: parameter file {other}: no entry for "
                    "/frame/controller_node (its keys: /frame/sim_node; give "
                    "'/frame/controller_node:', 'controller_node:' or '/**:')")


@pytest.mark.skipif(not api.has_rclpy(), reason="rclpy not installed")
@pytest.mark.parametrize(("node_backend", "tools"), [("dds", "rclpy"), ("rclpy", "dds")])
def test_the_other_vendor_is_named_as_the_cause(ros_domain: int, monkeypatch: pytest.MonkeyPatch,
                                                node_backend: str, tools: str) -> None:
    proc = start_controller(node_backend, monkeypatch)
    try:
        monkeypatch.setenv("STILLFRAME_RMW", tools)
        line = one_error(run_stillframe("param", "get", "controller_node", "command_limit",
                                        "--timeout", "3"))
    finally:
        proc.terminate()
        finish(proc)
    ours, theirs = {"rclpy": "Fast DDS", "dds": "Cyclone DDS"}[tools], {
        "rclpy": "Fast DDS", "dds": "Cyclone DDS"}[node_backend]
    assert line.endswith(f"(it runs on {theirs} and this client on {ours}, and parameter "
                         "services do not cross DDS vendors: run the call with "
                         f"STILLFRAME_RMW={node_backend})"), line
