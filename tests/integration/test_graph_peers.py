"""Other writers and tools on the graph (issue 26, item 3), with real rclpy peer processes.

- A peer that only creates a publisher on ``pendulum/torque_cmd`` and never writes (what ``ros2
  topic pub`` before its first message, a Foxglove publish panel or a teleop tool do) changes
  nothing: the lock-step run equals the one-process loop to the last bit on both backends
  (rclpy's message info has no writer GID: the simulator decides from the sequence numbers of
  what arrives), and a real-time run on rclpy refuses no command.
- A peer that starts writing during the run, at its own pace (``ros2 topic pub -r 5``), is
  refused, counted and named, on rclpy too, and the lock-step run is still the one-process
  loop's to the last bit.
"""

from __future__ import annotations

import asyncio
import functools
import importlib.util
import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.loop.writer_gate import REASONS
from stillframe.monitor.foxglove_client import Capture, capture
from tests.support.middleware import child_env, finish, start_python, wait_for_line
from tests.support.nodes import SCENES, SHORT_LQG, read_lines, run_loop_beside, run_loop_until
from tests.support.scenes import thesis_scene
from tests.support.waits import HANG_S

BACKENDS = ("rclpy", "dds") if importlib.util.find_spec("rclpy") else ("dds",)

#: a real rclpy peer with a publisher on the command topic that never writes
IDLE_PEER = """
import signal
import rclpy
from geometry_msgs.msg import WrenchStamped
rclpy.init()
node = rclpy.create_node("idle_teleop", namespace="/frame")
pub = node.create_publisher(WrenchStamped, "pendulum/torque_cmd", 10)
stop = []
signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
print("ready", flush=True)
while not stop:
    rclpy.spin_once(node, timeout_sec=0.05)
print("sent", 0, flush=True)
"""

#: ``ros2 topic pub -r 5 /frame/pendulum/torque_cmd``, started during the run: a fixed 5 N m at
#: 5 Hz, stamped 0, from the moment its writer has matched every reader of the topic, the
#: simulator's among them, and the loop's ``/clock`` has passed 0.5 s. It prints ``wrote N WALL_NS
#: CLOCK_NS`` for each sample it writes, and ``named VALUE WALL_NS`` when the simulator's
#: ``/diagnostics`` first gives a new ``pendulum_torque_cmd_ignored_writers``.
PUB_PEER = """
import signal, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rosgraph_msgs.msg import Clock
rclpy.init()
node = rclpy.create_node("topic_pub", namespace="/frame")
clock = [0]
node.create_subscription(Clock, "/clock", lambda m: clock.__setitem__(0, m.clock.sec * 10**9
                         + m.clock.nanosec), rclpy.qos.qos_profile_sensor_data)
named = []
def on_status(msg):
    for status in msg.status:
        value = {kv.key: kv.value for kv in status.values}.get(
            "pendulum_torque_cmd_ignored_writers", "")
        if status.name.endswith("/sim_node") and value and value not in named:
            named.append(value)
            print("named", value, time.time_ns(), flush=True)
node.create_subscription(DiagnosticArray, "/diagnostics", on_status, 100)
pub = node.create_publisher(WrenchStamped, "pendulum/torque_cmd", 10)
cmd = WrenchStamped()
cmd.wrench.torque.z = 5.0
stop = []
signal.signal(signal.SIGTERM, lambda *a: stop.append(1))

def reaches_sim():
    readers = node.get_subscriptions_info_by_topic(pub.topic_name)
    return (any(r.node_name == "sim_node" for r in readers)
            and pub.get_subscription_count() >= len(readers))

print("ready", flush=True)
sent, due = 0, 0.0
while not stop:
    rclpy.spin_once(node, timeout_sec=0.02)
    if clock[0] >= 5 * 10**8 and time.monotonic() >= due and reaches_sim():
        wall = time.time_ns()
        pub.publish(cmd)
        sent, due = sent + 1, time.monotonic() + 0.2
        print("wrote", sent, wall, clock[0], flush=True)
print("sent", sent, flush=True)
"""


def writer_refusals(gate: dict) -> int:
    return sum(gate[f"rejected_{r}"] for r in REASONS)


@functools.cache
def reference(overrides: tuple[str, ...] = tuple(SHORT_LQG)) -> Any:
    """The one-process loop of the scene the tests launch (with ``overrides``)."""
    return run_closed_loop(thesis_scene("thesis_lqg", list(overrides)))


def loop_beside(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, backend: str, peer: str, *,
                log: list[str] | None = None,
                **params: Any) -> tuple[dict, dict[str, np.ndarray], int, dict]:
    """The three nodes on ``backend`` (sim_node pinned to controller_node, as a launch pins it)
    beside the ``peer`` script: the result, the histories, what the peer sent, and the torque
    command's gate report (the simulator's log lines appended to ``log``)."""
    monkeypatch.setenv("STILLFRAME_RMW", backend)
    result, hist, sent = run_loop_beside(tmp_path, peer, "thesis_lqg", SHORT_LQG, log=log,
                                         command_writer="controller_node", **params)
    return result, hist, sent, result["command_gates"]["pendulum/torque_cmd"]


@pytest.mark.slow
@pytest.mark.parametrize("backend", BACKENDS)
def test_an_idle_publisher_on_the_command_topic_changes_nothing(
        ros_domain: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, backend: str) -> None:
    sim_log: list[str] = []
    result, hist, _, gate = loop_beside(tmp_path, monkeypatch, backend, IDLE_PEER, log=sim_log)
    np.testing.assert_array_equal(hist["command"], reference().command)
    np.testing.assert_array_equal(hist["truth"], reference().truth)
    assert writer_refusals(gate) == 0 and gate["ignored_writers"] == ""
    assert result["complete"] is True, [line for line in sim_log if "error" in line]


@pytest.mark.slow
@pytest.mark.parametrize("backend", [pytest.param(b, marks=pytest.mark.long if b == "dds" else ())
                                     for b in BACKENDS])   # the run is rclpy's
def test_an_idle_publisher_changes_nothing_in_real_time(
        ros_domain: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, backend: str) -> None:
    """The issue's run (rclpy): every command refused as ``ambiguous_writer`` before, the
    reductions negative. Now no command is refused for its writer and the controller's commands
    are applied. How many come in time, and so the reductions, depend on the machine's load (the
    degraded verdict reports that, not this test); so that a loaded machine's late commands
    cannot zero the actuation, the simulator's safe states are off here (no miss-rate guard, a
    command timeout longer than the run): every command it takes is applied."""
    result, _, _, gate = loop_beside(tmp_path, monkeypatch, backend, IDLE_PEER, mode="realtime",
                                     command_miss_limit=0.0, command_timeout_periods=1_000_000)
    assert writer_refusals(gate) == 0 and gate["ignored_writers"] == ""
    assert gate["writer"] == "/frame/controller_node"
    assert result["peak_command"] > 0
    assert result["degraded_samples"] == result["safe_state_samples"] == 0


#: a lock-step run far longer than the test lets it run: it is stopped once what the test checks
#: has happened, however long that takes on a loaded machine
LONG_LQG = ["duration=600", "controller.start=3", "evaluation.window=2"]

#: how long [s] of sim time the run goes on at least: one second of control
CONTROLLED_UNTIL_S = 4.0

#: the simulator's log line that names a writer it refuses
REFUSING = "pendulum/torque_cmd: refusing the samples of another writer: "


def log_stamp_ns(line: str) -> int:
    """The wall time of a log line ``[LEVEL] [SEC.NSEC] [name]: …`` (rcutils' console format)."""
    sec, nsec = line.split("] [", 2)[1].split(".")
    return int(sec) * 10**9 + int(nsec)


@pytest.mark.slow
@pytest.mark.parametrize("backend", BACKENDS)
def test_a_writing_peer_is_refused_counted_and_named(
        ros_domain: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, backend: str) -> None:
    """The peer writes once its writer has matched the simulator's reader, into a lock-step run
    that the test stops (SIGINT) only when the simulator's log and ``/diagnostics`` (as the peer
    receives it) name the peer, the peer has written 3 samples and the run has controlled for
    a second. Its samples are refused and counted, the names came within one second of the first
    refused sample, and the run is the one-process loop's to the last bit."""
    monkeypatch.setenv("STILLFRAME_RMW", backend)
    peer = start_python(PUB_PEER)
    wait_for_line(peer, "ready")
    said = read_lines(peer.stdout)

    def done(sim_log: list[str]) -> bool:
        wrote = [line.split() for line in said.lines if line.startswith("wrote")]
        return (len(wrote) >= 3 and int(wrote[-1][3]) >= CONTROLLED_UNTIL_S * 1e9
                and any(REFUSING + "/frame/topic_pub" in line for line in sim_log)
                and any(line.startswith("named /frame/topic_pub") for line in said.lines))
    peer_err = read_lines(peer.stderr)
    try:
        result, hist, sim_log = run_loop_until(tmp_path, "thesis_lqg", LONG_LQG, done,
                                               command_writer="controller_node")
    finally:
        peer.send_signal(signal.SIGTERM)
        peer.wait(120)
        said.reader.join(10)
        peer_err.reader.join(10)
    assert peer.returncode == 0 and said.lines[-1].startswith("sent"), peer_err.text()[-2000:]
    sent = int(said.lines[-1].split()[-1])
    gate = result["command_gates"]["pendulum/torque_cmd"]
    # refused and counted; nothing else refused
    assert 0 < writer_refusals(gate) <= sent, (gate, sent)
    assert result["rejected_commands"] == writer_refusals(gate)
    assert gate["writer"] == "/frame/controller_node"
    assert gate["ignored_writers"] == "/frame/topic_pub", gate
    # named within one second of the first refused sample. The first line naming the peer
    # counts the N samples refused so far: the peer's last writes before the line (one more may
    # have been on its way), so the first of them was written no earlier than the (N+1)-th last
    # write before the line. It names the node, or its writer's GID while the graph has not
    # named the peer's node yet (the only eProsima writer, vendor 01.0f: on dds the graph takes
    # seconds to name a Fast DDS participant; on rclpy, whose samples carry no GID, the gate
    # gives the graph's GID of the writer that is not the loop's own); so does /diagnostics, as
    # the peer received it. A line (and a status) before it may say "unnamed" (the graph shows no
    # such writer yet), never rmw's placeholder
    refusing = [line for line in sim_log if REFUSING in line]
    first = next(line for line in refusing if REFUSING + "/frame/topic_pub (" in line
                 or REFUSING + "010f" in line)
    assert all(REFUSING + "unnamed (" in line for line in refusing[:refusing.index(first)]), (
        refusing)
    logged_ns, refused = log_stamp_ns(first), int(first.rsplit("(", 1)[1].split()[0])
    writes = [int(line.split()[2]) for line in said.lines if line.startswith("wrote")]
    before = [t for t in writes if t <= logged_ns]
    first_ns = before[max(0, len(before) - refused - 1)]
    assert logged_ns - first_ns <= 10**9, (first, writes)
    # /diagnostics is published with each of those lines: its first status naming the peer,
    # after only "unnamed" ones (seen once in CI, on rclpy)
    statuses = [line.split() for line in said.lines if line.startswith("named")]
    diagnosed = next(words for words in statuses if words[1] == "/frame/topic_pub"
                     or words[1].startswith("010f"))
    assert all(words[1] == "unnamed" for words in statuses[:statuses.index(diagnosed)]), statuses
    assert int(diagnosed[2]) - first_ns <= 10**9, (diagnosed, writes)
    # control unaffected: the samples run equal the one-process loop's, a second of control in
    steps = result["steps"]
    assert result["complete"] is False and hist["t"][-1] >= CONTROLLED_UNTIL_S
    np.testing.assert_array_equal(hist["command"], reference(tuple(LONG_LQG)).command[:steps])
    np.testing.assert_array_equal(hist["truth"], reference(tuple(LONG_LQG)).truth[:steps])


def launch(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "stillframe", "launch", str(SCENES / "thesis_lqg.yaml"),
         *[a for o in SHORT_LQG for a in ("--set", o)], "--backend", "dds", *args],
        env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)


@pytest.mark.slow
@pytest.mark.long      # two whole launches side by side, each waiting out the other
def test_two_launches_on_one_domain_never_both_stall(ros_domain: int) -> None:
    """Started in the same instant: the later launcher refuses with one line naming the earlier
    one (exit 2), before starting any node when discovery shows it within ``LOOK_S``, at once
    when it shows it later (a loaded machine); the earlier one runs to its end, undisturbed in
    the first case. A third one, started while the first runs, refuses too."""
    # real time, so that the first still runs when the third starts however loaded the machine
    # is (a lock-step run of a few seconds can end first); the third starts seconds later
    held = ["--mode", "realtime", *[a for o in ("duration=30", "controller.start=15",
                                                "evaluation.window=10") for a in ("--set", o)]]
    first, second = launch("--json", *held), launch("--json", *held)
    deadline = time.monotonic() + 120
    while first.poll() is None and second.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    if first.poll() is not None:        # the one that ended is the later one: swap
        first, second = second, first
    _out, err = second.communicate(timeout=120)
    assert second.returncode == 2, err[-2000:]
    lines = [line for line in err.splitlines() if line.startswith("stillframe launch")]
    assert len(lines) == 1 and "another stillframe loop is running on ROS_DOMAIN_ID=" \
        f"{ros_domain}: /_stillframe_launch_{first.pid}_" in lines[0], err
    third = launch()
    err3 = third.communicate(timeout=120)[1]
    assert first.poll() is None, "the first launch ended before the third looked"
    result = json.loads(first.communicate(timeout=300)[0])
    assert first.returncode == 0
    if "started sim_node" not in err:   # refused before its nodes ran
        assert result["complete"] is True
    assert third.returncode == 2 and f"/_stillframe_launch_{first.pid}_" in err3, err3


#: ``ros2 topic pub -r 10 /chatter std_msgs/msg/String``: a peer on a topic of its own
CHATTER = """
import signal, time
import rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("talker")
pub = node.create_publisher(String, "/chatter", 10)
stop = []
signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
print("ready", flush=True)
sent = 0
while not stop:
    pub.publish(String(data=f"hello {sent}"))
    sent += 1
    time.sleep(0.1)
print("sent", sent, flush=True)
"""


def stillframe_cli(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "stillframe", *args], env=child_env(),
                            cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def imu_stamps(bag: Path) -> list[int]:
    """The header stamps [ns] of ``/frame/floor1/imu`` in ``bag``, read with rosbags."""
    with AnyReader([bag]) as reader:
        imu = [c for c in reader.connections if c.topic == "/frame/floor1/imu"]
        return [(m := reader.deserialize(raw, c.msgtype)).header.stamp.sec * 10**9
                + m.header.stamp.nanosec for c, _, raw in reader.messages(connections=imu)]


def stop_all(procs: list[subprocess.Popen], sig: int = signal.SIGINT) -> None:
    """Send ``sig`` to each process still running, then wait for each (killed after
    :data:`HANG_S`)."""
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(sig)
    for proc in procs:
        try:
            proc.wait(HANG_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.mark.slow
@pytest.mark.skipif("rclpy" not in BACKENDS, reason="rclpy not installed")
def test_the_loop_keeps_controlling_beside_tools(ros_domain: int, tmp_path: Path) -> None:
    """Beside a lock-step launch with its recorder: ``stillframe topic echo`` and ``topic hz``,
    a second recorder of every topic (named apart: a launch waits for its own recorder, found
    by the name ``stillframe_recorder``), ``stillframe monitor`` with a Foxglove client
    subscribed to every topic, and a real rclpy talker on ``/chatter``. The launch runs until
    every tool has shown what it got (echo the IMU's stamps past a second of control, hz a rate,
    the Foxglove client IMU messages), however long that takes, and is then stopped with
    SIGINT (Ctrl-C). The samples run are the one-process loop's to the last bit without a
    lock-step timeout; the launch's bag holds every one, the second recorder's every one from
    its first."""
    monitor = stillframe_cli("monitor", "--port", "0", "--max-rate", "0")
    ready = ""
    while "Monitor ready" not in ready:
        ready = monitor.stderr.readline()
        assert ready or monitor.poll() is None, "monitor did not start"
    url = ready.split("foxglove ", 1)[1].split(",")[0].strip()
    done, seen = asyncio.Event(), Capture()
    client = threading.Thread(target=asyncio.run, args=(capture(url, None, done, seen),),
                              daemon=True)
    client.start()
    tools = [stillframe_cli("topic", "echo", "/frame/floor1/imu", "--field", "header.stamp.sec"),
             stillframe_cli("topic", "hz", "/frame/state_estimate"),
             stillframe_cli("record", "-o", str(tmp_path / "second"), "--all",
                            "--node-name", "second_recorder"),
             start_python(CHATTER)]
    assert tools[-1].stdout.readline().strip() == "ready"
    said = [read_lines(proc.stdout) for proc in (*tools, monitor)]
    logs = [read_lines(proc.stderr) for proc in (*tools, monitor)]
    echo, hz = said[0], said[1]
    out = tmp_path / "out"
    run = subprocess.Popen(
        [sys.executable, "-m", "stillframe", "launch", str(SCENES / "thesis_lqg.yaml"),
         *[a for o in LONG_LQG for a in ("--set", o)], "--record", str(tmp_path / "bag"),
         "--out", str(out),
         # eight processes on the machine: a late sample is waited for, not held over
         "--lockstep-timeout", "10"],
        env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    run_log = read_lines(run.stderr)
    read_lines(run.stdout)

    def everyone_got_theirs() -> bool:
        secs = [int(line) for line in echo.lines if line.strip().isdigit()]
        return (bool(secs) and max(secs) >= CONTROLLED_UNTIL_S
                and any("average rate" in line for line in hz.lines)
                and bool(seen.messages.get("/frame/floor1/imu")))
    try:
        deadline = time.monotonic() + 300
        while not everyone_got_theirs():
            assert run.poll() is None, f"the launch ended first: {run_log.text()[-3000:]}"
            assert time.monotonic() < deadline, (echo.lines[-5:], hz.lines, run_log.text()[-3000:])
            time.sleep(0.05)
    finally:
        stop_all([run])
        stop_all(tools[:-1])
        stop_all(tools[-1:], signal.SIGTERM)
        stop_all([monitor])
        client.join(10)
        for lines in (*said, *logs, run_log):
            lines.reader.join(10)
    assert run.returncode == 130, run_log.text()[-3000:]    # Ctrl-C, every node stopped
    result = json.loads((out / "result.json").read_text())
    steps = result["steps"]
    assert result["complete"] is False, [line for line in run_log.lines if "error" in line]
    with np.load(out / "result.npz") as data:
        assert data["t"][-1] >= CONTROLLED_UNTIL_S
        np.testing.assert_array_equal(data["command"], reference(tuple(LONG_LQG)).command[:steps])
        np.testing.assert_array_equal(data["truth"], reference(tuple(LONG_LQG)).truth[:steps])
    # every sample the loop ran (the one it was stopped in too, published before it waited)
    period = round(1e9 / 32)
    grid = [k * period for k in range(steps + 1)]
    recorded = imu_stamps(tmp_path / "bag")
    assert recorded in (grid[:-1], grid), (len(recorded), steps)
    second = imu_stamps(tmp_path / "second")
    first = round(second[0] / period) if second else len(grid)
    assert second == grid[first:first + len(second)] and first + len(second) >= steps, (
        second[:3], len(second), steps)
    assert sum(line.strip() == "---" for line in echo.lines) >= 5
    assert int(said[3].lines[-1].split()[-1]) > 0      # the talker wrote all along
    assert all(proc.returncode == 0 for proc in tools[:-1]), [lg.text()[-500:] for lg in logs]


@pytest.mark.slow
def test_a_real_time_run_beside_a_writer_names_it_and_strict_fails(ros_domain: int) -> None:
    """A real-time launch beside a peer writing commands (every one it writes lacks the run's
    token): the simulator's log and ``/diagnostics`` name the peer, the JSON lists it under
    ``foreign_writers`` and not as the controller's refused commands (they are not the
    figures'), and ``--strict`` ends the run with exit code 6 and one line naming it."""
    peer = start_python(PUB_PEER)
    wait_for_line(peer, "ready")
    try:
        run = launch("--mode", "realtime", "--strict", "--json")
        out, err = run.communicate(timeout=300)
    finally:
        peer.send_signal(signal.SIGTERM)
        sent = int(finish(peer, timeout=120)[0].split()[-1])
    result = json.loads(out)
    gate = result["command_gates"]["pendulum/torque_cmd"]
    assert sent > 0 and gate["rejected_foreign_writer"] > 0, gate
    assert writer_refusals(gate) == gate["rejected_foreign_writer"]
    assert not any("refused commands" in reason for reason in result["degraded_reasons"])
    # the simulator's log and /diagnostics name the peer (by its GID until the graph has its
    # name: the only eProsima, vendor 01.0f, writer)
    named = [line for line in err.splitlines()
             if "[sim_node]" in line and "pendulum/torque_cmd: refusing the samples of a "
             "foreign writer (without the run's token): " in line]
    assert named and ("/frame/topic_pub" in named[-1] or ": 010f" in named[-1]), err[-3000:]
    sim = next(v for k, v in result["diagnostics"].items() if k.endswith("sim_node"))
    assert sim["pendulum_torque_cmd_ignored_writers"] != ""
    assert {"node": "/frame/sim_node", "topic": "/frame/pendulum/torque_cmd",
            "writers": ["/frame/topic_pub"], "refused": gate["rejected_foreign_writer"]} in (
        result["foreign_writers"])
    lines = [line for line in err.splitlines() if line.startswith("stillframe launch")]
    assert run.returncode == 6
    assert len(lines) == 1 and lines[0].startswith("stillframe launch: error: ")
    assert "/frame/topic_pub on /frame/pendulum/torque_cmd" in lines[0], err[-2000:]
