"""``stillframe topic list|echo|hz`` against a known publisher in another process."""

from __future__ import annotations

import re

import pytest
import yaml

from tests.support.middleware import finish, run_stillframe, start_python, wait_for_line

RATE_HZ = 50.0
PUBLISHER = f"""
from stillframe.contract import messages
from stillframe.middleware.api import create_node, spin
from stillframe.middleware.taps import TappedPublisher
node = create_node("truth_pub", namespace="/frame")
pub = TappedPublisher(node, "sensor_msgs/msg/JointState", "state_truth", "default")
cov = node.create_publisher("std_msgs/msg/Float64MultiArray", "state_estimate/covariance", 10)
k = [0]
def tick():
    k[0] += 1
    pub.publish(messages.new(
        "sensor_msgs/msg/JointState",
        header=messages.new("std_msgs/msg/Header", stamp=messages.time_msg(7 * 10**9 + 5),
                            frame_id="frame"),
        name=["x1", "x2", "x3", "phi"], position=[0.5, -1.25, 2.0, 0.125]))
node.create_timer({1 / RATE_HZ}, tick)
print("ready", flush=True)
spin(node)
node.destroy_node()
"""


@pytest.fixture
def publisher(ros_domain: int):
    proc = start_python(PUBLISHER)
    wait_for_line(proc, "ready")
    yield proc
    proc.terminate()
    finish(proc)


@pytest.mark.slow
# the tools on dds against a dds publisher is the long run; rclpy's reads it across vendors
@pytest.mark.parametrize("tool_backend", [pytest.param("dds", marks=pytest.mark.long), "rclpy"])
def test_list_echo_and_hz(publisher: object, tool_backend: str,
                          monkeypatch: pytest.MonkeyPatch) -> None:
    """The publisher is on the dds backend; the tools on either (rclpy: across vendors)."""
    if tool_backend == "rclpy":
        pytest.importorskip("rclpy", reason="real rclpy is installed by `make setup` ([ros])")
    monkeypatch.setenv("STILLFRAME_RMW", tool_backend)
    listed = run_stillframe("topic", "list", "-t", "--spin-time", "2")
    assert listed.returncode == 0, listed.stderr
    lines = listed.stdout.splitlines()
    assert "/frame/state_truth [sensor_msgs/msg/JointState]" in lines
    assert "/frame/state_estimate/covariance [std_msgs/msg/Float64MultiArray]" in lines
    assert lines == sorted(lines)
    plain = run_stillframe("topic", "list", "--spin-time", "2")
    assert "/frame/state_truth" in plain.stdout.splitlines()
    # the monitor tap is hidden, as ros2 topic list hides names with a token starting with '_'
    assert not any("_monitor" in line for line in lines + plain.stdout.splitlines())
    hidden = run_stillframe("topic", "list", "--include-hidden-topics", "--spin-time", "2")
    assert {"/frame/state_truth", "/_monitor/frame/state_truth"} <= set(
        hidden.stdout.splitlines())

    echo = run_stillframe("topic", "echo", "/frame/state_truth", "--once", "--timeout", "20")
    assert echo.returncode == 0, echo.stderr
    # ros2's warning only when nothing publishes: the daemon's settled graph shows the publisher
    # a fresh tool node has not found within its first half second
    assert "does not appear to be published" not in echo.stderr, echo.stderr
    assert echo.stdout.rstrip().endswith("---")
    document = yaml.safe_load(echo.stdout.rstrip().removesuffix("---"))
    assert document == {
        "header": {"stamp": {"sec": 7, "nanosec": 5}, "frame_id": "frame"},
        "name": ["x1", "x2", "x3", "phi"],
        "position": [0.5, -1.25, 2.0, 0.125],
        "velocity": [],
        "effort": [],
    }
    field = run_stillframe("topic", "echo", "/frame/state_truth", "--once",
                           "--field", "header.stamp", "--timeout", "20")
    assert field.stdout == "sec: 7\nnanosec: 5\n---\n"

    hz = run_stillframe("topic", "hz", "/frame/state_truth", "--duration", "3.5",
                        "--timeout", "20")
    assert hz.returncode == 0, hz.stderr
    assert "does not appear to be published" not in hz.stderr, hz.stderr
    rates = [float(r) for r in re.findall(r"^average rate: ([0-9.]+)$", hz.stdout, re.M)]
    assert len(rates) >= 2
    windows = [int(w) for w in re.findall(r"window: (\d+)$", hz.stdout, re.M)]
    assert windows == sorted(windows)
    # A timer-driven publisher at 50 Hz: generous bounds, the machine is shared.
    assert 0.6 * RATE_HZ < rates[-1] < 1.4 * RATE_HZ


@pytest.mark.slow
def test_bad_input_gives_one_line_errors(publisher: object) -> None:
    cases = [
        (["topic", "echo", "/frame//state_truth", "--once"], "invalid topic name"),
        (["topic", "echo", "/frame/state_truth", "--once", "--field", "header.nope",
          "--timeout", "20"], "std_msgs/msg/Header has no field 'nope'"),
        (["topic", "echo", "/nobody/here", "--timeout", "1"],
         "no publisher of topic /nobody/here appeared within 1 s"),
        (["topic", "hz", "/frame/state_truth", "--window", "0"], "--window must be >= 1"),
    ]
    for args, message in cases:
        result = run_stillframe(*args)
        assert result.returncode == 2, (args, result.stderr)
        assert message in result.stderr
        assert "Traceback" not in result.stderr
        # ros2's warning where nothing publishes the topic, and only there
        assert ("WARNING: topic [/nobody/here] does not appear to be published yet"
                in result.stderr) == ("/nobody/here" in args), result.stderr
        errors = [line for line in result.stderr.splitlines() if "error:" in line]
        assert len(errors) == 1
