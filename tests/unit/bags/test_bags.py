"""Bag files on disk (no middleware): metadata, MCAP contents, reading, info, corrupt bags.

Independent sources: ``metadata.yaml`` parsed with plain PyYAML, the MCAP file read with the
``mcap`` package (not ``rosbags``), bags written directly with ``rosbags``'s own ``Writer``, and
the ROS 2 Jazzy type hash of ``sensor_msgs/msg/Imu`` as rmw publishes it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime as T
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from stillframe.bags.storage import BagWriter, bag_summary, format_summary, read_bag
from stillframe.errors import BagError, InputError
from stillframe.locations import REPO_ROOT

ROOT = REPO_ROOT
TS = get_typestore(Stores.ROS2_JAZZY)
# sensor_msgs/msg/Imu's type hash in ROS 2 Jazzy (what rmw puts in USER_DATA typehash=...).
IMU_RIHS01 = "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"
INFINITE = T(9223372036, 854775807)
SENSOR_QOS = Qos(QosHistory.KEEP_LAST, 5, QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
                 INFINITE, INFINITE, QosLiveliness.AUTOMATIC, INFINITE, False)
DEFAULT_QOS = SENSOR_QOS._replace(depth=10, reliability=QosReliability.RELIABLE)
T0 = 1_700_000_000_123_456_789


def imu(stamp_ns: int, ax: float) -> bytes:
    t = TS.types
    msg = t["sensor_msgs/msg/Imu"](
        t["std_msgs/msg/Header"](t["builtin_interfaces/msg/Time"](*divmod(stamp_ns, 10**9)),
                                 "floor1"),
        t["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0), np.full(9, -1.0),
        t["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0), np.full(9, -1.0),
        t["geometry_msgs/msg/Vector3"](ax, 0.0, 0.0), np.eye(3).ravel() * 1e-4)
    return bytes(TS.serialize_cdr(msg, "sensor_msgs/msg/Imu"))


def joint_state(stamp_ns: int, phi: float) -> bytes:
    t = TS.types
    msg = t["sensor_msgs/msg/JointState"](
        t["std_msgs/msg/Header"](t["builtin_interfaces/msg/Time"](*divmod(stamp_ns, 10**9)), ""),
        ["pendulum"], np.array([phi]), np.zeros(0), np.zeros(0))
    return bytes(TS.serialize_cdr(msg, "sensor_msgs/msg/JointState"))


def sample_messages() -> list[tuple[str, int, bytes]]:
    """30 Imu at 100 Hz interleaved with 10 JointState at 33.3 Hz, in time order."""
    msgs = [("/frame/floor1/imu", T0 + k * 10_000_000, imu(T0 + k * 10_000_000, 0.1 * k))
            for k in range(30)]
    msgs += [("/frame/pendulum/joint_states", T0 + 5_000_000 + k * 30_000_000,
              joint_state(T0 + k * 30_000_000, -0.01 * k)) for k in range(10)]
    return sorted(msgs, key=lambda m: m[1])


TYPES = {"/frame/floor1/imu": "sensor_msgs/msg/Imu",
         "/frame/pendulum/joint_states": "sensor_msgs/msg/JointState"}


@pytest.fixture
def our_bag(tmp_path: Path) -> Path:
    path = tmp_path / "ours"
    with BagWriter(path, TS) as bag:
        bag.add_topic("/frame/floor1/imu", TYPES["/frame/floor1/imu"], [SENSOR_QOS])
        bag.add_topic("/frame/pendulum/joint_states", TYPES["/frame/pendulum/joint_states"],
                      [DEFAULT_QOS, SENSOR_QOS])
        for topic, stamp, data in sample_messages():
            bag.write(topic, stamp, data)
    return path


def run_cli(*args: str, tz: str = "UTC") -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "TZ": tz}
    return subprocess.run([sys.executable, "-m", "stillframe", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)


def test_metadata_is_rosbag2_v9_mcap_with_counts_qos_and_hashes(our_bag: Path) -> None:
    meta = yaml.safe_load((our_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9
    assert meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == 40
    assert meta["starting_time"]["nanoseconds_since_epoch"] == T0
    assert meta["duration"]["nanoseconds"] == 290_000_000  # last Imu at T0 + 0.29 s
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert {k: t["message_count"] for k, t in topics.items()} == {
        "/frame/floor1/imu": 30, "/frame/pendulum/joint_states": 10}
    for name, entry in topics.items():
        tm = entry["topic_metadata"]
        assert tm["type"] == TYPES[name]
        assert tm["serialization_format"] == "cdr"
        assert tm["type_description_hash"] == TS.hash_rihs01(TYPES[name])
    assert topics["/frame/floor1/imu"]["topic_metadata"]["type_description_hash"] == IMU_RIHS01
    imu_qos = topics["/frame/floor1/imu"]["topic_metadata"]["offered_qos_profiles"]
    assert imu_qos == [{
        "history": "keep_last", "depth": 5, "reliability": "best_effort",
        "durability": "volatile", "deadline": {"sec": 9223372036, "nsec": 854775807},
        "lifespan": {"sec": 9223372036, "nsec": 854775807}, "liveliness": "automatic",
        "liveliness_lease_duration": {"sec": 9223372036, "nsec": 854775807},
        "avoid_ros_namespace_conventions": False}]
    js_qos = topics["/frame/pendulum/joint_states"]["topic_metadata"]["offered_qos_profiles"]
    assert [(q["reliability"], q["depth"]) for q in js_qos] == [("reliable", 10),
                                                                ("best_effort", 5)]


def test_mcap_file_read_by_the_mcap_package(our_bag: Path) -> None:
    files = list(our_bag.glob("*.mcap"))
    assert len(files) == 1
    with files[0].open("rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        assert summary.statistics.message_count == 40
        schemas = {s.name: s.encoding for s in summary.schemas.values()}
        assert schemas == {t: "ros2msg" for t in TYPES.values()}
        channel_qos = {c.topic: yaml.safe_load(c.metadata["offered_qos_profiles"])
                       for c in summary.channels.values()}
        assert channel_qos["/frame/floor1/imu"][0]["reliability"] == "best_effort"
        got = [(ch.topic, m.log_time, m.data)
               for _, ch, m in reader.iter_messages(log_time_order=True)]
    assert got == sample_messages()


def test_metadata_names_the_distro_jazzy(our_bag: Path) -> None:
    """As ``ros2 bag record`` on Jazzy writes it: in ``metadata.yaml`` and in the MCAP file's
    ``rosbag2`` metadata record (read by the ``mcap`` package)."""
    meta = yaml.safe_load((our_bag / "metadata.yaml").read_text())
    assert meta["rosbag2_bagfile_information"]["ros_distro"] == "jazzy"
    with next(our_bag.glob("*.mcap")).open("rb") as f:
        records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    embedded = yaml.safe_load(records["rosbag2"]["serialized_metadata"])
    assert embedded["ros_distro"] == "jazzy"


def test_read_back_bytes_stamps_order_and_decoded_values(our_bag: Path) -> None:
    got = list(read_bag(our_bag, TS, decode=True))
    assert [(m.topic, m.stamp, m.data) for m in got] == sample_messages()
    assert [m.type for m in got] == [TYPES[m.topic] for m in got]
    imus = [m.msg for m in got if m.topic == "/frame/floor1/imu"]
    assert [m.linear_acceleration.x for m in imus] == pytest.approx([0.1 * k for k in range(30)])
    assert imus[7].header.stamp.sec * 10**9 + imus[7].header.stamp.nanosec == T0 + 70_000_000
    only = list(read_bag(our_bag, TS, topics=["/frame/pendulum/joint_states"]))
    assert [m.msg for m in only] == [None] * 10
    assert len(only) == 10


def test_unknown_topic_filter_is_an_input_error(our_bag: Path) -> None:
    with pytest.raises(InputError, match="no topic /nope"):
        list(read_bag(our_bag, TS, topics=["/nope"]))


def test_writer_refuses_an_existing_directory(our_bag: Path) -> None:
    with pytest.raises(InputError, match="exists already"):
        BagWriter(our_bag, TS)


def test_writer_closes_the_bag_when_interrupted(tmp_path: Path) -> None:
    """A KeyboardInterrupt inside the ``with`` block still leaves a complete, readable bag."""
    path = tmp_path / "interrupted"
    with pytest.raises(KeyboardInterrupt), BagWriter(path, TS) as bag:
        bag.add_topic("/frame/floor1/imu", "sensor_msgs/msg/Imu", [SENSOR_QOS])
        for k in range(7):
            bag.write("/frame/floor1/imu", T0 + k, imu(T0 + k, float(k)))
        raise KeyboardInterrupt
    assert [m.stamp - T0 for m in read_bag(path, TS)] == list(range(7))


def write_with_rosbags(path: Path, storage: StoragePlugin = StoragePlugin.MCAP) -> None:
    """The sample messages written by rosbags's own Writer, not through stillframe."""
    with Writer(path, version=9, storage_plugin=storage) as writer:
        conns = {topic: writer.add_connection(topic, msgtype, typestore=TS,
                                              offered_qos_profiles=[DEFAULT_QOS])
                 for topic, msgtype in TYPES.items()}
        for topic, stamp, data in sample_messages():
            writer.write(conns[topic], stamp, data)


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_bag_written_by_rosbags_reads_and_summarises(tmp_path: Path,
                                                     storage: StoragePlugin) -> None:
    """Also the sqlite3 storage (the default before Iron) reads."""
    path = tmp_path / "foreign"
    write_with_rosbags(path, storage)
    assert [(m.topic, m.stamp, m.data) for m in read_bag(path, TS)] == sample_messages()
    summary = bag_summary(path, TS)
    assert summary.storage_id == storage.name.lower()
    assert (summary.start_ns, summary.end_ns, summary.message_count) == (
        T0, T0 + 290_000_000, 40)
    assert [(t.name, t.count, t.type_description_hash) for t in summary.topics] == [
        ("/frame/floor1/imu", 30, IMU_RIHS01),
        ("/frame/pendulum/joint_states", 10, TS.hash_rihs01("sensor_msgs/msg/JointState"))]
    assert summary.topics[0].offered_qos == [DEFAULT_QOS]


@pytest.mark.processes
def test_bag_info_text_like_ros2_bag_info(tmp_path: Path) -> None:
    """Line by line the layout of rosbag2's ``format_bag_meta_data`` (Jazzy), in UTC."""
    path = tmp_path / "foreign"
    write_with_rosbags(path)
    out = run_cli("bag", "info", str(path))
    assert out.returncode == 0, out.stderr
    size = sum(p.stat().st_size for p in path.iterdir())
    assert out.stdout.splitlines() == [
        "",
        "Files:             foreign.mcap",
        f"Bag size:          {size / 1024:.1f} KiB",
        "Storage id:        mcap",
        "ROS Distro:        rosbags",
        "Duration:          0.290000000s",
        "Start:             Nov 14 2023 22:13:20.123456789 (1700000000.123456789)",
        "End:               Nov 14 2023 22:13:20.413456789 (1700000000.413456789)",
        "Messages:          40",
        "Topic information: Topic: /frame/floor1/imu | Type: sensor_msgs/msg/Imu | Count: 30 | "
        "Serialization Format: cdr",
        "                   Topic: /frame/pendulum/joint_states | Type: sensor_msgs/msg/JointState"
        " | Count: 10 | Serialization Format: cdr",
        "Service:           0",
        "Service information: ",
    ]


@pytest.mark.processes
def test_bag_info_json(our_bag: Path) -> None:
    out = run_cli("bag", "info", str(our_bag), "--json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert (doc["start_ns"], doc["end_ns"], doc["duration_ns"]) == (
        T0, T0 + 290_000_000, 290_000_000)
    assert doc["message_count"] == 40
    assert doc["storage_id"] == "mcap"
    topics = {t["name"]: t for t in doc["topics"]}
    assert topics["/frame/floor1/imu"]["count"] == 30
    assert topics["/frame/floor1/imu"]["offered_qos_profiles"][0]["depth"] == 5
    assert topics["/frame/floor1/imu"]["type_description_hash"] == IMU_RIHS01


def test_service_event_topics_listed_as_services() -> None:
    """A ``/_service_event`` topic is a service in ``ros2 bag info``, not counted as a message."""
    from stillframe.bags.storage import BagSummary, TopicSummary
    summary = BagSummary(
        path="b", files=["b_0.mcap"], size_bytes=100, storage_id="mcap", ros_distro="jazzy",
        start_ns=0, duration_ns=0, message_count=7, topics=[
            TopicSummary("/add/_service_event", "example_interfaces/srv/AddTwoInts_Event", 4,
                         "cdr", ""),
            TopicSummary("/chatter", "std_msgs/msg/String", 3, "cdr", "")])
    lines = format_summary(summary).splitlines()
    assert "Messages:          3" in lines
    assert lines[-2:] == [
        "Service:           1",
        "Service information: Service: /add | Type: example_interfaces/srv/AddTwoInts | "
        "Event Count: 4 | Serialization Format: cdr"]


def _truncate(path: Path, keep: float) -> Path:
    mcap = next(path.glob("*.mcap"))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: int(len(data) * keep)])
    return mcap


CORRUPTIONS = {
    "truncated_half": lambda p: _truncate(p, 0.5),
    "truncated_tail": lambda p: _truncate(p, 0.99),
    "garbage_mcap": lambda p: (next(p.glob("*.mcap")).write_bytes(b"\0" * 4096),
                               next(p.glob("*.mcap")))[1],
    "missing_mcap": lambda p: (next(p.glob("*.mcap")).unlink(), p / "foreign.mcap")[1],
    "bad_yaml": lambda p: ((p / "metadata.yaml").write_text("rosbag2_bagfile_information: [\n"),
                           p / "metadata.yaml")[1],
    "wrong_yaml": lambda p: ((p / "metadata.yaml").write_text("version: 9\n"),
                             p / "metadata.yaml")[1],
    "missing_yaml": lambda p: ((p / "metadata.yaml").unlink(), p / "metadata.yaml")[1],
}


@pytest.mark.processes
@pytest.mark.parametrize("kind", sorted(CORRUPTIONS))
def test_corrupt_bag_is_a_one_line_error_naming_the_file(tmp_path: Path, kind: str) -> None:
    path = tmp_path / "foreign"
    write_with_rosbags(path)
    culprit = CORRUPTIONS[kind](path)
    with pytest.raises(BagError, match=str(culprit)):
        list(read_bag(path, TS))
    out = run_cli("bag", "info", str(path))
    assert out.returncode == BagError.exit_code == 3
    assert "Traceback" not in out.stderr
    assert out.stderr.count("\n") == 1
    assert str(culprit) in out.stderr


@pytest.mark.processes
def test_missing_directory_is_a_bag_error(tmp_path: Path) -> None:
    out = run_cli("bag", "info", str(tmp_path / "nope"))
    assert (out.returncode, out.stderr.count("\n")) == (BagError.exit_code, 1)
    assert str(tmp_path / "nope") in out.stderr


JAZZY_METADATA = """\
rosbag2_bagfile_information:
  version: 9
  storage_identifier: mcap
  duration:
    nanoseconds: {duration}
  starting_time:
    nanoseconds_since_epoch: {start}
  message_count: {count}
  topics_with_message_count:
    - topic_metadata:
        name: /chatter
        type: std_msgs/msg/String
        serialization_format: cdr
        offered_qos_profiles:
          - history: keep_last
            depth: 7
            reliability: reliable
            durability: transient_local
            deadline:
              sec: 9223372036
              nsec: 854775807
            lifespan:
              sec: 9223372036
              nsec: 854775807
            liveliness: automatic
            liveliness_lease_duration:
              sec: 9223372036
              nsec: 854775807
            avoid_ros_namespace_conventions: false
        type_description_hash: {hash}
      message_count: {count}
  compression_format: ""
  compression_mode: ""
  relative_file_paths:
    - {name}_0.mcap
  files:
    - path: {name}_0.mcap
      starting_time:
        nanoseconds_since_epoch: {start}
      duration:
        nanoseconds: {duration}
      message_count: {count}
  custom_data: ~
  ros_distro: jazzy
"""


def string_cdr(text: str) -> bytes:
    """std_msgs/msg/String in little-endian CDR, built by hand."""
    raw = text.encode() + b"\0"
    return b"\x00\x01\x00\x00" + len(raw).to_bytes(4, "little") + raw


def write_like_ros2_bag_record(path: Path, n: int = 25,
                               channel_qos: str | None = None) -> list[tuple[int, str]]:
    """A bag laid out as Jazzy's ``ros2 bag record`` writes it, with the ``mcap`` package:
    ``<dir>_0.mcap`` with zstd chunks, publish_time (sender) before log_time (receive)."""
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter

    meta = JAZZY_METADATA.format(duration=(n - 1) * 100_000_000, start=T0 + 12_345, count=n,
                                 name=path.name, hash=TS.hash_rihs01("std_msgs/msg/String"))
    if channel_qos is None:  # the same profile as in metadata.yaml, as a YAML string
        channel_qos = yaml.safe_dump(yaml.safe_load(meta)["rosbag2_bagfile_information"][
            "topics_with_message_count"][0]["topic_metadata"]["offered_qos_profiles"])
    path.mkdir()
    sent = [(T0 + k * 100_000_000 + 12_345, f"hello {k}") for k in range(n)]
    with (path / f"{path.name}_0.mcap").open("wb") as f:
        writer = McapWriter(f, compression=CompressionType.ZSTD, chunk_size=256)
        writer.start(profile="ros2", library="libmcap 1.4.0")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
        channel = writer.register_channel("/chatter", "cdr", schema, metadata={
            "offered_qos_profiles": channel_qos,
            "topic_type_hash": TS.hash_rihs01("std_msgs/msg/String")})
        for k, (stamp, text) in enumerate(sent):
            writer.add_message(channel, log_time=stamp, data=string_cdr(text),
                               publish_time=stamp - 50_000, sequence=k)
        writer.finish()
    (path / "metadata.yaml").write_text(meta)
    return sent


def test_bag_as_ros2_bag_record_writes_it_reads_and_summarises(tmp_path: Path) -> None:
    path = tmp_path / "rosbag2_2026_01_01-00_00_00"
    sent = write_like_ros2_bag_record(path)
    got = list(read_bag(path, TS, decode=True))
    assert [(m.stamp, m.msg.data) for m in got] == sent
    assert [m.data for m in got] == [string_cdr(text) for _, text in sent]
    summary = bag_summary(path, TS)
    assert summary.files == [f"{path.name}_0.mcap"]
    assert (summary.ros_distro, summary.storage_id) == ("jazzy", "mcap")
    assert (summary.start_ns, summary.end_ns) == (sent[0][0], sent[-1][0])
    (topic,) = summary.topics
    assert (topic.name, topic.count) == ("/chatter", 25)
    assert [(q.depth, q.durability.name) for q in topic.offered_qos] == [(7, "TRANSIENT_LOCAL")]


def test_incomplete_qos_record_is_a_bag_error_naming_the_mcap(tmp_path: Path) -> None:
    path = tmp_path / "partial"
    write_like_ros2_bag_record(path, channel_qos="- history: keep_last\n  depth: 7\n")
    with pytest.raises(BagError, match=f"{path / 'partial_0.mcap'}: unreadable bag file"):
        bag_summary(path, TS)


def test_the_recorders_write_path_writes_what_rosbags_writer_writes(tmp_path: Path) -> None:
    """``BagWriter.writer_of`` (the recorder's per-message call into the ``mcap`` writer) against
    rosbags' own ``Writer.write`` on the same messages, across several chunks: the ``mcap``
    package reads the same records, and ``metadata.yaml`` says the same counts and times."""
    rng = np.random.default_rng(3)
    sent = [("/a" if rng.random() < 0.6 else "/b", T0 + 1000 * i, imu(T0 + i, float(i)))
            for i in range(12_000)]      # about 5 MB: five chunks
    fast = tmp_path / "fast"
    with BagWriter(fast, TS) as bag:
        for topic in ("/a", "/b"):
            bag.add_topic(topic, "sensor_msgs/msg/Imu")
        writers = {topic: bag.writer_of(topic) for topic in ("/a", "/b")}
        for topic, stamp, data in sent:
            writers[topic](stamp, data)
    reference = tmp_path / "reference"
    with Writer(reference, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        conns = {t: bag.add_connection(t, "sensor_msgs/msg/Imu", typestore=TS)
                 for t in ("/a", "/b")}
        for topic, stamp, data in sent:
            bag.write(conns[topic], stamp, data)

    def records(path: Path) -> list[tuple[str, int, int, bytes]]:
        with (path / f"{path.name}.mcap").open("rb") as stream:
            return [(channel.topic, message.log_time, message.publish_time, message.data)
                    for _, channel, message in make_reader(stream).iter_messages()]

    assert records(fast) == records(reference) == [(t, s, s, d) for t, s, d in sent]

    def meta(path: Path) -> dict:
        info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        return {"count": info["message_count"], "start": info["starting_time"],
                "duration": info["duration"],
                "topics": {t["topic_metadata"]["name"]: t["message_count"]
                           for t in info["topics_with_message_count"]}}

    assert meta(fast) == meta(reference)
