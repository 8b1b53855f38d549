"""record / play over real DDS: separate ``stillframe`` processes on loopback, one random
``ROS_DOMAIN_ID`` per test (``tests.support.middleware.ros_domain``).

The source bag is written with ``rosbags``'s own ``Writer`` (not through stillframe), so the
first ``play`` also shows that foreign bags play; what comes back is compared byte for byte.
"""

# No "from __future__ import annotations": cyclonedds resolves the IDL struct annotations.

import dataclasses
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy
from cyclonedds.qos import Qos as DdsQos
from cyclonedds.topic import Topic
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime as T
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from stillframe.errors import BagError
from stillframe.locations import REPO_ROOT as ROOT
from stillframe.middleware import api
from stillframe.middleware.discovery import cyclone_config
from tests.support.middleware import child_env
from tests.support.waits import HANG_S

TS = get_typestore(Stores.ROS2_JAZZY)
INF = T(9223372036, 854775807)
SENSOR = Qos(QosHistory.KEEP_LAST, 5, QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
             INF, INF, QosLiveliness.AUTOMATIC, INF, False)
RELIABLE = SENSOR._replace(depth=10, reliability=QosReliability.RELIABLE)
IMU, JS = "/frame/floor1/imu", "/frame/state_estimate"
T0 = 1_750_000_000_000_000_000

def _header(stamp_ns: int, frame: str) -> object:
    t = TS.types
    return t["std_msgs/msg/Header"](t["builtin_interfaces/msg/Time"](*divmod(stamp_ns, 10**9)),
                                    frame)


def imu(k: int, stamp_ns: int) -> bytes:
    t = TS.types
    msg = t["sensor_msgs/msg/Imu"](
        _header(stamp_ns, f"floor1_{k}"), t["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
        np.full(9, -1.0), t["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0), np.full(9, -1.0),
        t["geometry_msgs/msg/Vector3"](np.sin(0.1 * k), 0.0, 0.0), np.eye(3).ravel() * 1e-4)
    return bytes(TS.serialize_cdr(msg, "sensor_msgs/msg/Imu"))


def joint_state(k: int, stamp_ns: int) -> bytes:
    msg = TS.types["sensor_msgs/msg/JointState"](
        _header(stamp_ns, ""), ["x1", "x2", "x3", "phi"], np.array([k, 0.0, 0.0, -k]),
        np.array([0.5 * k, 0.0, 0.0, 0.0]), np.zeros(0))
    return bytes(TS.serialize_cdr(msg, "sensor_msgs/msg/JointState"))


def write_source(path: Path, n_imu: int, n_js: int, period_ns: int) -> list[tuple[str, int, bytes]]:
    """A bag written with rosbags directly: Imu (sensor-data QoS) and JointState (reliable)
    interleaved; the header stamps are the bag stamps."""
    msgs = [(IMU, T0 + k * period_ns, imu(k, T0 + k * period_ns)) for k in range(n_imu)]
    msgs += [(JS, T0 + k * 2 * period_ns + period_ns // 2,
              joint_state(k, T0 + k * 2 * period_ns + period_ns // 2)) for k in range(n_js)]
    msgs.sort(key=lambda m: m[1])
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {IMU: writer.add_connection(IMU, "sensor_msgs/msg/Imu", typestore=TS,
                                            offered_qos_profiles=[SENSOR]),
                 JS: writer.add_connection(JS, "sensor_msgs/msg/JointState", typestore=TS,
                                           offered_qos_profiles=[RELIABLE])}
        for topic, stamp, data in msgs:
            writer.write(conns[topic], stamp, data)
    return msgs


def read_all(path: Path) -> list[tuple[str, int, bytes]]:
    """Messages of a bag through rosbags's Reader (not stillframe.bags.storage)."""
    with Reader(path) as reader:
        return [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]


def topic_metadata(path: Path) -> dict[str, dict]:
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return {t["topic_metadata"]["name"]: {**t["topic_metadata"], "count": t["message_count"]}
            for t in meta["topics_with_message_count"]}


class Proc:
    """A ``stillframe`` subprocess whose stderr (the node's log) is collected as it comes."""

    def __init__(self, env: dict[str, str], *args: str) -> None:
        self.popen = subprocess.Popen(
            [sys.executable, "-m", "stillframe", *args], cwd=ROOT, env=env,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._collect, daemon=True)
        self._reader.start()

    def _collect(self) -> None:
        assert self.popen.stderr is not None
        for line in self.popen.stderr:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, text: str, count: int = 1, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while sum(text in line for line in self.lines) < count:
            if self.popen.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise AssertionError(f"no {count}x {text!r} in log:\n" + "\n".join(self.lines))
            time.sleep(0.05)

    def finish(self, sig: int | None = None, timeout: float = 60.0) -> int:
        if sig is not None:
            self.popen.send_signal(sig)
        code = self.popen.wait(timeout)
        self._reader.join(5)
        return code

    def stop(self) -> None:
        if self.popen.poll() is None:
            self.popen.kill()
            self.popen.wait()


@pytest.fixture
def env(ros_domain: int) -> dict[str, str]:
    """A private ROS domain for this test, the dds backend and the repo on the path."""
    return child_env()


def record_while_playing(env: dict[str, str], source: Path, out: Path, *play_args: str,
                         topics: tuple[str, ...] = (IMU, JS),
                         backends: tuple[str, str] = ("dds", "dds")) -> tuple[Proc, Proc]:
    """``record`` then ``play``, each on its backend (recorder's, player's)."""
    recorder = Proc({**env, "STILLFRAME_RMW": backends[0]}, "record", "-o", str(out), *topics)
    recorder.wait_for("Recording to")
    player = Proc({**env, "STILLFRAME_RMW": backends[1]}, "play", str(source), "--delay", "2",
                  *play_args)
    recorder.wait_for("Subscribed to topic", count=2)
    return recorder, player


@pytest.mark.slow
# one vendor alone is the long run: the two mixes exercise both backends' recorder and player
@pytest.mark.parametrize("backends", [pytest.param(("dds", "dds"), marks=pytest.mark.long),
                                      ("rclpy", "dds"), ("dds", "rclpy")],
                         ids=["dds", "record-rclpy-play-dds", "record-dds-play-rclpy"])
def test_record_play_record_keeps_every_message_stamp_and_order(
        env: dict[str, str], tmp_path: Path, backends: tuple[str, str]) -> None:
    """bag A (rosbags) -play-> record B -play-> record C: B and C hold exactly A's messages,
    per topic in A's order, with A's header stamps (in the bytes) and A's spacing in time;
    also with the recorder on one vendor (Fast DDS through rclpy, or Cyclone) and the player
    on the other."""
    if "rclpy" in backends:
        pytest.importorskip("rclpy", reason="real rclpy is installed by `make setup` ([ros])")
    source = tmp_path / "A"
    msgs = write_source(source, n_imu=100, n_js=50, period_ns=20_000_000)  # 2 s of data
    bags = [source]
    for name in ("B", "C"):
        recorder, player = record_while_playing(env, bags[-1], tmp_path / name,
                                                backends=backends)
        try:
            assert player.finish() == 0, "\n".join(player.lines)
            time.sleep(0.5)
            assert recorder.finish(signal.SIGINT) == 0, "\n".join(recorder.lines)
        finally:
            player.stop()
            recorder.stop()
        bags.append(tmp_path / name)

    for path in bags[1:]:
        got = read_all(path)
        for topic in (IMU, JS):
            assert [d for t, _, d in got if t == topic] == [d for t, _, d in msgs if t == topic]
        # Played with the recorded spacing: the receive stamps span at least half of A's 2 s
        # (a player that ignored the timing delivers all 150 in milliseconds; on a loaded machine
        # the first samples can arrive late and bunched, so the bound is not tighter).
        stamps = [s for _, s, _ in got]
        assert stamps == sorted(stamps)
        assert stamps[-1] - stamps[0] >= 0.5 * (msgs[-1][1] - msgs[0][1])
        meta = topic_metadata(path)
        assert (meta[IMU]["count"], meta[JS]["count"]) == (100, 50)
        assert meta[IMU]["type_description_hash"] == TS.hash_rihs01("sensor_msgs/msg/Imu")
        # The player offered what the source's publishers offered; the recorder saw that.
        assert [(q["reliability"], q["durability"]) for q in meta[IMU]["offered_qos_profiles"]] \
            == [("best_effort", "volatile")]
        assert [(q["reliability"], q["durability"]) for q in meta[JS]["offered_qos_profiles"]] \
            == [("reliable", "volatile")]


@pytest.mark.slow
# the recorder handles both signals alike; SIGTERM runs by default in test_record_signals
@pytest.mark.parametrize("sig", [signal.SIGINT,
                                 pytest.param(signal.SIGTERM, marks=pytest.mark.long)])
def test_interrupt_keeps_every_message_received(env: dict[str, str], tmp_path: Path,
                                                sig: signal.Signals) -> None:
    """Ctrl-C (or SIGTERM) in the middle of a stream: the bag is complete and holds exactly the
    first k messages published (reliable topic, so nothing in between may be missing), k = the
    count the recorder reports. Recording ``--all``."""
    source = tmp_path / "A"
    msgs = write_source(source, n_imu=0, n_js=400, period_ns=10_000_000)  # 8 s of JointState
    recorder, player = record_while_playing(env, source, tmp_path / "B", topics=("--all",))
    try:
        time.sleep(2.0 + 2.0)  # the player's delay, then about half the stream
        assert recorder.finish(sig) == 0, "\n".join(recorder.lines)
        player.finish(signal.SIGINT)
    finally:
        player.stop()
        recorder.stop()
    got = read_all(tmp_path / "B")
    k = len(got)
    assert k > 0
    assert [d for _, _, d in got] == [d for _, _, d in msgs[:k]]
    assert any(f"Recorded {k} messages" in line for line in recorder.lines), recorder.lines
    published = [line for line in player.lines if "Published" in line]
    assert published and int(published[0].split("Published ")[1].split()[0]) >= k


@pytest.mark.slow
def test_play_clock_publishes_bag_time_and_sim_time_recording_follows_it(
        env: dict[str, str], tmp_path: Path) -> None:
    """``play --clock``: /clock carries bag time, from the bag's start to its end; a recorder
    with ``--use-sim-time`` stamps the messages with that time, not with the system time."""
    source = tmp_path / "A"
    msgs = write_source(source, n_imu=0, n_js=50, period_ns=20_000_000)
    clock_rec = Proc(env, "record", "-o", str(tmp_path / "clock"), "/clock")
    sim_rec = Proc(env, "record", "-o", str(tmp_path / "sim"), JS, "--use-sim-time")
    clock_rec.wait_for("Recording to")
    sim_rec.wait_for("Recording to")
    player = Proc(env, "play", str(source), "--delay", "2", "--clock", "100")
    try:
        clock_rec.wait_for("Subscribed to topic")
        sim_rec.wait_for("Subscribed to topic")
        assert player.finish() == 0
        time.sleep(0.3)
        assert clock_rec.finish(signal.SIGINT) == 0
        assert sim_rec.finish(signal.SIGINT) == 0
    finally:
        for proc in (player, clock_rec, sim_rec):
            proc.stop()
    start, end = msgs[0][1], msgs[-1][1]
    clock = [TS.deserialize_cdr(d, "rosgraph_msgs/msg/Clock").clock
             for _, _, d in read_all(tmp_path / "clock")]
    times = [c.sec * 10**9 + c.nanosec for c in clock]
    assert len(times) >= 10
    assert times == sorted(times)
    assert start <= times[0] and times[-1] <= end
    assert times[-1] - times[0] >= 0.5 * (end - start)
    sim = read_all(tmp_path / "sim")
    assert [d for _, _, d in sim] == [d for _, _, d in msgs]
    stamps = [s for _, s, _ in sim]
    assert stamps == sorted(stamps)
    assert start <= stamps[0] and stamps[-1] <= end  # bag time of 2025, not today


def add_sim_clock(path: Path, source: Path) -> None:
    """A copy of ``source`` with a ``/clock`` recorded beside it, as ``record --all`` beside a
    simulator has it: sim time from 0, one tick before each message."""
    types = {IMU: ("sensor_msgs/msg/Imu", SENSOR), JS: ("sensor_msgs/msg/JointState", RELIABLE),
             "/clock": ("rosgraph_msgs/msg/Clock", SENSOR._replace(depth=1))}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {topic: writer.add_connection(topic, kind, typestore=TS,
                                              offered_qos_profiles=[qos])
                 for topic, (kind, qos) in types.items()}
        for k, (topic, stamp, data) in enumerate(read_all(source)):
            sim = TS.types["rosgraph_msgs/msg/Clock"](
                TS.types["builtin_interfaces/msg/Time"](*divmod(k * 20_000_000, 10**9)))
            writer.write(conns["/clock"], stamp,
                         bytes(TS.serialize_cdr(sim, "rosgraph_msgs/msg/Clock")))
            writer.write(conns[topic], stamp, data)


@pytest.mark.slow
def test_play_clock_skips_a_recorded_clock_and_topics_select(env: dict[str, str],
                                                              tmp_path: Path) -> None:
    """A bag with a recorded ``/clock`` (sim time from 0) played with ``--clock``: ``/clock``
    carries only the bag time (2025), the note says why; ``--topics`` and ``--exclude`` play
    what they name, as ``ros2 bag play`` does."""
    write_source(tmp_path / "A", n_imu=20, n_js=10, period_ns=20_000_000)
    add_sim_clock(tmp_path / "C", tmp_path / "A")
    clock_rec = Proc(env, "record", "-o", str(tmp_path / "clock"), "--all")
    clock_rec.wait_for("Recording to")
    player = Proc(env, "play", str(tmp_path / "C"), "--delay", "2", "--clock", "100",
                  "--exclude", IMU)
    try:
        assert player.finish() == 0, "\n".join(player.lines)
        time.sleep(0.3)
        assert clock_rec.finish(signal.SIGINT) == 0
        only = Proc(env, "play", str(tmp_path / "C"), "--delay", "0", "--topics", IMU, "/clock")
        assert only.finish() == 0, "\n".join(only.lines)
    finally:
        for proc in (player, clock_rec):
            proc.stop()
    assert any("the bag's /clock is not played: --clock publishes the bag time" in line
               for line in player.lines), player.lines
    got = read_all(tmp_path / "clock")
    clock = [TS.deserialize_cdr(d, "rosgraph_msgs/msg/Clock").clock
             for t, _, d in got if t == "/clock"]
    assert len(clock) >= 10 and all(c.sec * 10**9 + c.nanosec >= T0 for c in clock)
    assert [d for t, _, d in got if t == JS] == [d for t, _, d in read_all(tmp_path / "A")
                                                 if t == JS]
    assert not [t for t, _, _ in got if t == IMU]
    # the 20 IMU messages and the 30 recorded ticks: without --clock, /clock is played
    assert any("Published 50 messages" in line for line in only.lines), only.lines


@pytest.mark.slow
def test_play_loop_at_rate_repeats_the_bag_faster(env: dict[str, str], tmp_path: Path) -> None:
    """``--loop --rate 4``: the recording is the bag's messages over and over (at least twice
    through), each pass taking between a quarter of the bag's span (less 10 %) and the span."""
    source = tmp_path / "A"
    msgs = write_source(source, n_imu=0, n_js=40, period_ns=20_000_000)  # 1.6 s
    recorder, player = record_while_playing(env, source, tmp_path / "B", "--loop", "--rate", "4")
    # a listener of its own counts what the player sent: the player stops once three passes
    # went out (forced, not a sleep that a loaded machine may not keep)
    node = api.create_node("loop_watch", backend="dds")
    seen: list[bytes] = []
    node.create_subscription("sensor_msgs/msg/JointState", JS,
                             lambda cdr, _info: seen.append(bytes(cdr)), "default", raw=True)
    try:
        api.spin_until(node, lambda: len(seen) >= 3 * len(msgs), 120)
        assert len(seen) >= 3 * len(msgs), "\n".join(player.lines)
        assert player.finish(signal.SIGINT) == 0, "\n".join(player.lines)
        time.sleep(0.5)
        assert recorder.finish(signal.SIGINT) == 0, "\n".join(recorder.lines)
    finally:
        player.stop()
        recorder.stop()
        node.destroy_node()
    got = read_all(tmp_path / "B")
    data = [d for _, _, d in msgs]
    passes, rest = divmod(len(got), len(data))
    assert passes >= 2
    assert [d for _, _, d in got] == data * passes + data[:rest]
    span = msgs[-1][1] - msgs[0][1]
    for p in range(passes):
        stamps = [s for _, s, _ in got[p * len(data):(p + 1) * len(data)]]
        assert 0.9 * span / 4 <= stamps[-1] - stamps[0] <= span


@pytest.mark.parametrize(("args", "named", "code"), [
    (["play", "{tmp}/nope"], "{tmp}/nope", BagError.exit_code),
    (["play", "{tmp}/A", "--rate", "0"], "--rate", 2),
    (["play", "{tmp}/A", "--clock", "-1"], "--clock", 2),
    (["play", "{tmp}/A", "--topics", "/frame/floor9/imu"], "--topics: /frame/floor9/imu", 2),
    (["play", "{tmp}/A", "--exclude", "nope"], "--exclude: /nope", 2),
    (["record", "-o", "{tmp}/new"], "--all", 2),
    (["record", "-o", "{tmp}/new", "--all", "/x"], "--all", 2),
    (["record", "-o", "{tmp}/A", "--all"], "{tmp}/A", 2),
    (["record", "-o", "{tmp}/new", "bad topic"], "bad topic", 2),
])
def test_bad_arguments_are_one_line_errors(env: dict[str, str], tmp_path: Path,
                                           args: list[str], named: str, code: int) -> None:
    write_source(tmp_path / "A", n_imu=3, n_js=0, period_ns=1_000_000)
    argv = [a.format(tmp=tmp_path) for a in args]
    out = subprocess.run([sys.executable, "-m", "stillframe", *argv],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=60)
    errors = [line for line in out.stderr.splitlines() if "error" in line]
    assert out.returncode == code, out.stderr
    assert "Traceback" not in out.stderr
    assert len(errors) == 1 and named.format(tmp=tmp_path) in errors[0], out.stderr
    assert not (tmp_path / "new").exists()


@dataclasses.dataclass
class DdsString(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    """std_msgs/msg/String as rmw_cyclonedds_cpp puts it on the wire, declared by hand."""

    data: str


def test_records_a_foreign_publisher_and_skips_a_different_type_hash(
        env: dict[str, str], ros_domain: int, tmp_path: Path) -> None:
    """Raw Cyclone DDS writers (not stillframe) named the ROS 2 way: the one announcing
    Jazzy's type hash of std_msgs/msg/String is recorded message for message; the one announcing
    another hash is not recorded (its bytes would not match the definition in the bag); a hidden
    topic (a monitor tap's name) is not recorded either, as ``ros2 bag record -a`` leaves it."""
    domain = Domain(ros_domain, cyclone_config())
    participant = DomainParticipant(ros_domain, qos=DdsQos(Policy.Userdata(data=b"enclave=/;")))
    recorder = Proc(env, "record", "-o", str(tmp_path / "B"), "--all")
    writers = {}
    try:
        for name, digest in (("frame/native", TS.hash_rihs01("std_msgs/msg/String")),
                             ("frame/foreign", "RIHS01_" + "ab" * 32),
                             ("_monitor/frame/native", TS.hash_rihs01("std_msgs/msg/String"))):
            qos = DdsQos(Policy.Reliability.Reliable(10**9), Policy.History.KeepLast(10),
                      Policy.Userdata(data=f"typehash={digest};".encode()))
            writers[name] = DataWriter(
                participant, Topic(participant, f"rt/{name}", DdsString), qos)
        recorder.wait_for("Subscribed to topic '/frame/native'")
        recorder.wait_for("/frame/foreign: publishers announce type hash RIHS01_abab")
        deadline = time.monotonic() + HANG_S
        while not writers["frame/native"].get_matched_subscriptions():
            assert time.monotonic() < deadline, "the recorder never matched"
            time.sleep(0.05)
        for k in range(20):
            for name, writer in writers.items():
                writer.write(DdsString(f"{name.rsplit('/', 1)[1]} {k}"))
            # each sample acknowledged before the next: a recorder slowed by load loses none of
            # a history of 10 (forced, rather than hoping 20 fit in flight)
            assert writers["frame/native"].wait_for_acks(10**10), "not acknowledged"
        assert recorder.finish(signal.SIGINT) == 0, "\n".join(recorder.lines)
    finally:
        recorder.stop()
        del writers, participant, domain
    got = read_all(tmp_path / "B")
    assert {t for t, _, _ in got} == {"/frame/native"}
    assert [TS.deserialize_cdr(d, "std_msgs/msg/String").data for _, _, d in got] == [
        f"native {k}" for k in range(20)]
    assert set(topic_metadata(tmp_path / "B")) == {"/frame/native"}
    assert not any("_monitor" in line for line in recorder.lines), recorder.lines
