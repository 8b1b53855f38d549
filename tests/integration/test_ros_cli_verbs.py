"""``stillframe node|topic info|topic pub|param|daemon`` against a real rclpy peer process.

The peer is plain rclpy (Fast DDS), written the way a ROS 2 user writes a node, and it prints
its own view of itself (rclpy's ``TopicEndpointInfo`` strings, its services, what it receives,
its parameters once set): the independent source the tools' answers are compared with. The
tools run on either backend (``dds``: across vendors). Parameter services do not cross vendors
(docs/middleware.md), so the ``param`` verbs on ``dds`` are checked against a ``dds`` peer.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest
import yaml

from tests.support.middleware import finish, run_stillframe, start_python, wait_for_line

pytest.importorskip("rclpy", reason="real rclpy is installed by `make setup` ([ros])")

PEER = """
import json, sys
import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.qos import qos_profile_sensor_data
from std_msgs.msg import Float64, String

rclpy.init()
node = rclpy.create_node("talker", namespace="/cli_peer")
node.declare_parameter("gain", 1.5)
node.declare_parameter("label", "x")
node.declare_parameter("limits.upper", 3)
node.declare_parameter("fixed", 2.0, ParameterDescriptor(read_only=True))
chatter = node.create_publisher(String, "chatter", 10)
node.create_publisher(Float64, "fast", qos_profile_sensor_data)
node.create_subscription(Float64, "cmd", lambda m: print(f"got {m.data!r}", flush=True), 10)
node.create_timer(0.1, lambda: chatter.publish(String(data="hi")))
node.add_post_set_parameters_callback(
    lambda ps: print("set " + json.dumps({p.name: p.value for p in ps}), flush=True))
own = lambda q: sorted((n, sorted(t)) for n, t in q("talker", "/cli_peer"))
print("ready " + json.dumps({
    "chatter": [str(i) for i in node.get_publishers_info_by_topic("/cli_peer/chatter")],
    "publishers": own(node.get_publisher_names_and_types_by_node),
    "subscribers": own(node.get_subscriber_names_and_types_by_node),
    "servers": own(node.get_service_names_and_types_by_node),
}), flush=True)
rclpy.spin(node)
"""

DDS_PEER = """
from stillframe.middleware.api import create_node, spin
node = create_node("talker", namespace="/cli_peer", argv=["peer"])
node.declare_parameter("gain", 1.5)
node.declare_parameter("label", "x")
node.declare_parameter("limits.upper", 3)
node.declare_parameter("fixed", 2.0, read_only=True)
print("ready {}", flush=True)
spin(node)
node.destroy_node()
"""


def start_peer(code: str) -> tuple[subprocess.Popen, dict]:
    """The peer and its own view of itself (one line: two would wait in the pipe's buffer)."""
    proc = start_python(code)
    return proc, json.loads(wait_for_line(proc, "ready ").removeprefix("ready "))


@pytest.fixture
def tools(ros_domain: int, request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch):
    """The tools' backend; the graph daemon of this domain is stopped afterwards."""
    monkeypatch.setenv("STILLFRAME_RMW", request.param)
    yield request.param
    run_stillframe("daemon", "stop")


@pytest.fixture
def peer(ros_domain: int):
    proc, view = start_peer(PEER)
    yield proc, view
    if proc.returncode is None:
        proc.terminate()
        finish(proc)


def ok(*args: str) -> str:
    result = run_stillframe(*args)
    assert result.returncode == 0, (args, result.stderr)
    assert "middleware backend" not in result.stderr   # no banner without --verbose
    return result.stdout


def bad(*args: str) -> str:
    result = run_stillframe(*args)
    assert result.returncode == 2, (args, result.stdout, result.stderr)
    assert "Traceback" not in result.stderr
    errors = [line for line in result.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1, result.stderr
    return errors[0]


def section(text: str, title: str) -> list[str]:
    """The entries of one section of ``node info`` (``    name: types`` lines)."""
    lines = text.splitlines()
    start = lines.index(f"  {title}:") + 1
    entries = []
    for line in lines[start:]:
        if not line.startswith("    "):
            break
        entries.append(line.strip())
    return entries


def ros2_lines(entries: list) -> list[str]:
    return [f"{name}: {', '.join(types)}" for name, types in entries
            if not any(t.startswith("_") for t in name.split("/"))]


@pytest.mark.slow
@pytest.mark.parametrize("tools", ["rclpy", "dds"], indirect=True)
def test_graph_verbs_match_the_peers_own_view(peer: tuple, tools: str) -> None:
    _, view = peer
    # the first call starts the daemon and waits for discovery to settle: the answer is complete
    assert "/cli_peer/talker" in ok("node", "list").splitlines()
    assert "/cli_peer/chatter [std_msgs/msg/String]" in ok("topic", "list", "-t").splitlines()
    assert ok("daemon", "status") == "The daemon is running\n"
    hidden = ok("node", "list", "-a").splitlines()
    assert any(n.startswith("/_stillframe_daemon_") for n in hidden)
    assert ok("node", "list", "-c").strip() == str(len(ok("node", "list").splitlines()))

    info = ok("node", "info", "/cli_peer/talker")
    assert info.splitlines()[0] == "/cli_peer/talker"
    assert section(info, "Publishers") == ros2_lines(view["publishers"])
    assert section(info, "Subscribers") == ros2_lines(view["subscribers"])
    assert section(info, "Service Servers") == ros2_lines(view["servers"])
    assert section(info, "Service Clients") == []

    brief = ok("topic", "info", "/cli_peer/chatter")
    assert brief == "Type: std_msgs/msg/String\nPublisher count: 1\nSubscription count: 0\n"
    verbose = ok("topic", "info", "-v", "/cli_peer/chatter")
    blocks = verbose.split("\n\n")
    assert blocks[:2] == ["Type: std_msgs/msg/String", "Publisher count: 1"]
    expected = view["chatter"][0]                # node, type, hash, GID and QoS as rclpy prints
    if tools == "dds":  # Cyclone gives a discovered writer's history as its default, keep last 1
        expected = expected.replace("History (Depth): UNKNOWN", "History (Depth): KEEP_LAST (1)")
    assert blocks[2] == expected
    assert blocks[3] == "Subscription count: 0"

    assert "did you mean /cli_peer/chatter" in bad("topic", "info", "/cli_peer/chater")
    assert "did you mean /cli_peer/talker" in bad("node", "info", "/cli_peer/tallker")
    # echo of a misspelt topic: the suggestion instead of waiting for ever
    assert "did you mean /cli_peer/chatter" in bad("topic", "echo", "/cli_peer/chattter")
    assert ok("daemon", "stop") == "The daemon has been stopped\n"
    assert ok("daemon", "status") == "The daemon is not running\n"
    # without the daemon: a node of its own, once discovery settled
    assert "/cli_peer/talker" in ok("node", "list", "--no-daemon").splitlines()


def without_waiting(out: str) -> list[str]:
    lines = out.splitlines()
    return lines[1:] if lines[0] == "Waiting for at least 1 matching subscription(s)..." else lines


@pytest.mark.slow
@pytest.mark.parametrize("tools", ["rclpy", "dds"], indirect=True)
def test_topic_pub_reaches_the_peer(peer: tuple, tools: str) -> None:
    proc, _ = peer
    out = ok("topic", "pub", "/cli_peer/cmd", "std_msgs/msg/Float64", "data: 0.25", "--once")
    # ros2's lines; "Waiting for at least 1 matching subscription(s)..." first unless matched
    assert without_waiting(out)[:2] == ["publisher: beginning loop",
                                        "publishing #1: std_msgs.msg.Float64(data=0.25)"]
    out = ok("topic", "pub", "/cli_peer/cmd", "std_msgs/msg/Float64", "{data: -1}", "-t", "3",
             "-r", "20", "-p", "0")
    assert without_waiting(out) == ["publisher: beginning loop"]
    proc.terminate()
    received = finish(proc)[0].splitlines()
    assert received.count("got 0.25") == 1 and received.count("got -1.0") == 3
    assert "no field 'dat'" in bad("topic", "pub", "/x", "std_msgs/msg/Float64", "dat: 1", "-1")
    assert "expected a number" in bad("topic", "pub", "/x", "std_msgs/msg/Float64", "data: a",
                                      "-1")
    assert "did you mean std_msgs/msg/Float64" in bad("topic", "pub", "/x", "std_msgs/msg/Float46",
                                                      "data: 1", "-1")


def check_param_verbs(proc: subprocess.Popen, tmp_path: os.PathLike) -> None:
    result = run_stillframe("param", "list")
    listing = result.stdout.splitlines()
    assert result.returncode == 0 and "/cli_peer/talker:" in listing, (listing, result.stderr)
    start = listing.index("/cli_peer/talker:")
    names = [line.strip() for line in listing[start + 1:] if line.startswith("  ")]
    assert {"fixed", "gain", "label", "limits.upper", "use_sim_time"} <= set(names)
    dumped = yaml.safe_load(ok("param", "dump", "/cli_peer/talker"))
    params = dumped["/cli_peer/talker"]["ros__parameters"]
    assert {k: params[k] for k in ("fixed", "gain", "label", "limits")} == {
        "fixed": 2.0, "gain": 1.5, "label": "x", "limits": {"upper": 3}}
    file = tmp_path / "params.yaml"
    file.write_text("/cli_peer/talker:\n  ros__parameters:\n    gain: 4\n    fixed: 9.0\n"
                    "/**:\n  ros__parameters:\n    label: wild\n")
    result = run_stillframe("param", "load", "/cli_peer/talker", str(file))
    assert result.returncode == 1, result.stderr           # one parameter was refused
    assert "Set parameter gain successful" in result.stdout
    assert "Set parameter label successful" in result.stdout
    assert "Set parameter fixed failed" in result.stderr
    # the dump of the node now (the load sent an integer for a double as a double)
    params = yaml.safe_load(ok("param", "dump", "/cli_peer/talker"))["/cli_peer/talker"][
        "ros__parameters"]
    assert (params["gain"], params["label"], params["fixed"]) == (4.0, "wild", 2.0)
    assert "no answer" in bad("param", "dump", "/cli_peer/nobody", "--timeout", "1")


@pytest.mark.slow
@pytest.mark.parametrize("tools", ["rclpy"], indirect=True)
def test_param_verbs_on_an_rclpy_peer(peer: tuple, tools: str, tmp_path: os.PathLike) -> None:
    proc, _ = peer
    check_param_verbs(proc, tmp_path)
    proc.terminate()
    assert 'set {"gain": 4.0}' in finish(proc)[0].splitlines()


@pytest.mark.slow
@pytest.mark.parametrize("tools", ["dds"], indirect=True)
def test_param_verbs_on_a_dds_peer(ros_domain: int, tools: str, tmp_path: os.PathLike) -> None:
    proc, _ = start_peer(DDS_PEER)
    try:
        # a dds node's services, found from its request endpoints as rmw_cyclonedds names them
        info = ok("node", "info", "/cli_peer/talker")
        assert section(info, "Service Servers") == [
            f"/cli_peer/talker/{verb}_parameters: rcl_interfaces/srv/{kind}Parameters"
            for verb, kind in (("describe", "Describe"), ("get", "Get"), ("list", "List"),
                               ("set", "Set"))]
        check_param_verbs(proc, tmp_path)
    finally:
        proc.terminate()
        finish(proc)


def test_the_warm_path_loads_no_middleware(ros_domain: int) -> None:
    """A call answered by the daemon imports neither DDS, rclpy nor the message types: that is
    what makes it fast (``stillframe bench cli`` prints the figure)."""
    code = ("import sys; from stillframe.app.cli import main; main(['topic', 'list']); "
            "print(sorted(m for m in ('rclpy', 'cyclonedds', 'rosbags', 'numpy') "
            "if m in sys.modules))")
    try:
        assert ok("daemon", "start") == "The daemon has been started\n"
        assert ok("daemon", "start") == "The daemon is already running\n"
        result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                timeout=60, env=dict(os.environ))
        assert result.returncode == 0, result.stderr
        assert result.stdout.splitlines()[-1] == "[]"
    finally:
        run_stillframe("daemon", "stop")


@pytest.mark.parametrize(("env", "value", "message"), [
    ("ROS_DOMAIN_ID", "lab", "ROS_DOMAIN_ID='lab': expected an integer 0..232"),
    ("ROS_AUTOMATIC_DISCOVERY_RANGE", "NOPE", "ROS_AUTOMATIC_DISCOVERY_RANGE='NOPE': expected"),
])
@pytest.mark.parametrize("verb", [["topic", "list"], ["node", "list", "--no-daemon"],
                                  ["topic", "echo", "/x"], ["param", "dump", "/x"]])
def test_a_bad_environment_is_one_line_on_either_backend(
        ros_domain: int, monkeypatch: pytest.MonkeyPatch, env: str, value: str, message: str,
        verb: list[str]) -> None:
    """Checked before any middleware or daemon starts (rcl would raise a traceback for the
    domain and only warn for the range)."""
    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    monkeypatch.setenv(env, value)
    assert message in bad(*verb)


def test_the_backend_banner_only_with_verbose(ros_domain: int) -> None:
    quiet = run_stillframe("topic", "list", "--no-daemon", "--spin-time", "0.5")
    loud = run_stillframe("--verbose", "topic", "list", "--no-daemon", "--spin-time", "0.5")
    assert quiet.returncode == loud.returncode == 0, (quiet.stderr, loud.stderr)
    assert "middleware backend" not in quiet.stderr
    assert "middleware backend: dds" in loud.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["topic", "list", "--spin-time", "0"], "--spin-time must be > 0"),
    (["topic", "pub", "/x", "std_msgs/msg/Float64", "data: 1", "--rate", "0"], "--rate must be"),
    (["topic", "pub", "/x", "std_msgs/msg/Float64", "data: [", "-1"], "not valid YAML"),
    (["interface", "show", "std_msgs/msg/Nope"], "unknown message type std_msgs/msg/Nope"),
    (["param", "load", "/x", "/nonexistent.yaml"], "/nonexistent.yaml: cannot read the parameter"),
])
def test_bad_verb_arguments_are_one_line(ros_domain: int, args: list[str], message: str) -> None:
    assert message in bad(*args)


@pytest.mark.slow
@pytest.mark.parametrize("tools", ["rclpy"], indirect=True)
def test_the_daemons_graph_follows_nodes_that_come_and_go(tools: str) -> None:
    """The cache is the daemon's live view, not a snapshot of its start."""
    assert "/cli_peer/chatter" not in ok("topic", "list").splitlines()   # starts the daemon

    def listed_within(present: bool, seconds: float = 30.0) -> bool:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            if ("/cli_peer/chatter" in ok("topic", "list").splitlines()) == present:
                return True
            time.sleep(0.5)
        return False

    proc, _ = start_peer(PEER)
    try:
        assert listed_within(True)
    finally:
        proc.terminate()
        finish(proc)
    assert listed_within(False)


@pytest.mark.slow
@pytest.mark.parametrize("tools", ["dds"], indirect=True)
def test_param_list_names_the_nodes_of_the_other_vendor(peer: tuple, tools: str) -> None:
    result = run_stillframe("param", "list")
    assert result.returncode == 0, result.stderr
    assert "/cli_peer/talker: on Fast DDS, not reachable from Cyclone DDS" in result.stderr
    assert "/cli_peer/talker:" not in result.stdout.splitlines()
