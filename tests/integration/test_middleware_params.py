"""Parameters from ROS 2 parameter files and ``--ros-args``, as ``ros2 run`` passes them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from stillframe.errors import InputError
from stillframe.middleware import params
from stillframe.middleware.api import create_node
from stillframe.middleware.params import node_overrides, parse_ros_args
from tests.support.middleware import finish, start_python

PARAM_FILE = """
/**:
  ros__parameters:
    rate_hz: 100.0
    model:
      type: lumped
      elements: 3
sim_node:                 # rcl: means /sim_node, so it must not reach /rig/sim2
  ros__parameters:
    rate_hz: 1.0
/rig/sim2:
  ros__parameters:
    gains: [1, 2.5]
    names: [x1, x2]
    verbose: true
"""


@pytest.fixture
def param_file(tmp_path: Path) -> Path:
    path = tmp_path / "params.yaml"
    path.write_text(PARAM_FILE)
    return path


def test_parameter_file_and_ros_args_reach_the_node(ros_domain: int, param_file: Path) -> None:
    argv = ["prog", "user-arg", "--ros-args", "-r", "__ns:=/rig", "-r", "__node:=sim2",
            "--params-file", str(param_file), "-p", "model.elements:=5", "-p", "label:=hello",
            "--", "tail"]
    node = create_node("sim_node", namespace="/frame", argv=argv)
    try:
        assert (node.get_namespace(), node.get_name()) == ("/rig", "sim2")
        assert node.user_args == ["user-arg", "tail"]
        assert node.declare_parameter("rate_hz", 50.0).value == 100.0   # /** matched
        assert node.declare_parameter("model.type", "fe").value == "lumped"
        assert node.declare_parameter("model.elements", 1).value == 5   # -p after the file wins
        assert node.declare_parameter("gains", [0.0]).value == [1.0, 2.5]  # ints widened
        assert node.declare_parameter("names", ["a"]).value == ["x1", "x2"]
        assert node.declare_parameter("verbose", False).value is True
        assert node.declare_parameter("label", "").value == "hello"
        assert node.declare_parameter("untouched", 0.5).value == 0.5
        assert node.get_parameter("model.elements").value == 5
        assert node.get_parameter("use_sim_time").value is False  # declared by every node
        with pytest.raises(InputError, match="'rate_hz' of node /rig/sim2 is already declared"):
            node.declare_parameter("rate_hz", 1.0)
    finally:
        node.destroy_node()


def test_node_keys_follow_rcl_matching(param_file: Path) -> None:
    assert params.load_param_file(param_file, "/sim_node")["rate_hz"] == 1.0
    assert params.load_param_file(param_file, "/frame/sim_node")["rate_hz"] == 100.0
    assert "gains" not in params.load_param_file(param_file, "/frame/sim2")


ROS_RUN_NODE = """
import json
from stillframe.middleware.api import create_node
node = create_node("controller", namespace="/frame")
print(json.dumps([node.get_namespace(), node.get_name(),
                  node.declare_parameter("q_u", 1.0).value,
                  node.declare_parameter("start_s", 0).value]), flush=True)
node.destroy_node()
"""


def test_command_line_as_ros2_run_passes_it(ros_domain: int, param_file: Path) -> None:
    """``ros2 run pkg exe --ros-args ...`` hands the node ``sys.argv`` with these arguments."""
    proc = start_python(ROS_RUN_NODE, "--ros-args", "-p", "q_u:=1e-4", "--param", "start_s:=25",
                        "-r", "__ns:=/lab")
    out, err = finish(proc)
    assert proc.returncode == 0, err
    assert json.loads(out.strip().splitlines()[-1]) == ["/lab", "controller", 1e-4, 25]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("a: [1, 2\n", "not valid YAML: expected ',' or ']', but got '<stream end>' at line 2"),
        ("- just a list\n", "expected 'node_name: {ros__parameters: ...}'"),
        ("sim_node:\n  rate: 1\n", "node 'sim_node' has no 'ros__parameters' map"),
        ("/**:\n  ros__parameters:\n    mixed: [1, abc]\n", "parameter 'mixed'"),
        ("/**:\n  ros__parameters:\n    empty: []\n", "parameter 'empty'"),
    ],
)
def test_bad_parameter_files_name_the_file_and_the_problem(
    tmp_path: Path, content: str, message: str
) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(content)
    with pytest.raises(InputError) as info:
        params.load_param_file(path, "/sim_node")
    assert str(path) in str(info.value)
    assert message in str(info.value)


def test_missing_parameter_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.yaml"
    with pytest.raises(InputError, match=r"nope\.yaml: cannot read the parameter file \(No "):
        params.node_overrides(params.parse_ros_args(["--ros-args", "--params-file", str(path)]),
                              "/n")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--ros-args", "-p", "rate"], "expected NAME:=VALUE"),
        (["--ros-args", "-p"], "needs a value"),
        (["--ros-args", "--frobnicate", "1"], "unknown ROS argument '--frobnicate'"),
        (["--ros-args", "-p", ":=3"], "empty name"),
        (["--ros-args", "-p", "x:={a: 1}"], "not a ROS parameter value"),
    ],
)
def test_bad_ros_args(argv: list[str], message: str) -> None:
    with pytest.raises(InputError, match=message):
        params.parse_ros_args(argv)


def test_override_of_the_wrong_type_is_rejected_naming_parameter_and_node() -> None:
    store = params.Parameters("/frame/sim", {"rate_hz": "fast", "n": 2.5})
    with pytest.raises(InputError, match=r"'rate_hz' of node /frame/sim: expected float, got"):
        store.declare("rate_hz", 100.0)
    with pytest.raises(InputError, match=r"'n' of node /frame/sim: expected int, got 2.5"):
        store.declare("n", 1)
    with pytest.raises(InputError, match="not declared"):
        store.get("other")


@pytest.mark.parametrize("file_first", [True, False])
def test_precedence_of_files_and_p_equals_real_rclpy(file_first: bool, tmp_path: Path) -> None:
    """rcl files ``-p`` under ``/**``: a key naming the node wins over it whatever the order, and
    within ``/**`` the later assignment wins. The reference is real rclpy on the same arguments."""
    rclpy = pytest.importorskip("rclpy", reason="real rclpy is installed by `make setup` ([ros])")
    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters:\n    a: wild_file\n    b: wild_file\n"
                    "/**/sim_node:\n  ros__parameters:\n    a: node_file\n")
    cli = ["-p", "a:=cli", "-p", "b:=cli"]
    args = ["--params-file", str(path), *cli] if file_first else [*cli, "--params-file", str(path)]
    ours = node_overrides(parse_ros_args(["--ros-args", *args]), "/frame/sim_node")
    context = rclpy.Context()
    rclpy.init(args=["x", "--ros-args", *args], context=context)
    try:
        node = rclpy.create_node("sim_node", namespace="/frame", context=context)
        theirs = {n: node.declare_parameter(n, "unset").value for n in ("a", "b")}
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert ours == theirs == {"a": "node_file", "b": "cli" if file_first else "wild_file"}
