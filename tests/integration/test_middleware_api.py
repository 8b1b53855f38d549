"""Node API details: QoS profiles as rmw defines them, remaps, destroying endpoints, logging."""

from __future__ import annotations

import re
import time

import pytest

from stillframe.contract import messages
from stillframe.middleware import qos
from stillframe.middleware.api import create_node, spin_until
from stillframe.middleware.logger import Logger
from tests.support.waits import HANG_S


def test_profiles_are_rmws() -> None:
    """rmw/qos_profiles.h (Jazzy) and rclcpp's ClockQoS, with rmw's enum values."""
    sensor = (qos.History.KEEP_LAST, 5, qos.Reliability.BEST_EFFORT, qos.Durability.VOLATILE)
    default = (qos.History.KEEP_LAST, 10, qos.Reliability.RELIABLE, qos.Durability.VOLATILE)
    fields = ("history", "depth", "reliability", "durability")
    assert tuple(getattr(qos.SENSOR_DATA, f) for f in fields) == sensor
    assert tuple(getattr(qos.DEFAULT, f) for f in fields) == default
    assert qos.CLOCK.depth == 1 and qos.CLOCK.reliability == qos.Reliability.BEST_EFFORT
    assert qos.PARAMETERS.depth == 1000
    assert (int(qos.Reliability.RELIABLE), int(qos.Reliability.BEST_EFFORT)) == (1, 2)
    assert (int(qos.Durability.TRANSIENT_LOCAL), int(qos.Durability.VOLATILE)) == (1, 2)
    assert qos.as_profile(3) == qos.DEFAULT.with_depth(3)


def test_offered_qos_is_discovered_as_offered(ros_domain: int) -> None:
    node = create_node("offer", namespace="/frame", argv=["test"])
    try:
        latched = qos.QoSProfile(depth=1, durability=qos.Durability.TRANSIENT_LOCAL,
                                 deadline_ns=250_000_000)
        node.create_publisher("std_msgs/msg/Header", "latched", latched)
        node.create_publisher("sensor_msgs/msg/Imu", "floor1/imu", "sensor_data")
        found: dict = {}

        def discovered() -> bool:
            for topic in ("/frame/latched", "/frame/floor1/imu"):
                found[topic] = node.get_publishers_info_by_topic(topic)
            return all(found.values())

        assert spin_until(node, discovered, HANG_S)
        assert found["/frame/latched"][0].qos_profile == latched
        assert found["/frame/floor1/imu"][0].qos_profile == qos.SENSOR_DATA
        assert found["/frame/floor1/imu"][0].topic_type_hash == messages.TYPESTORE.hash_rihs01(
            "sensor_msgs/msg/Imu")
        assert ("offer", "/frame") in node.get_node_names_and_namespaces()
    finally:
        node.destroy_node()


def test_remap_and_destroy(ros_domain: int) -> None:
    node = create_node("remapper", namespace="/frame",
                       argv=["test", "--ros-args", "-r", "floor1/imu:=/rig/imu_a"])
    try:
        pub = node.create_publisher("sensor_msgs/msg/Imu", "floor1/imu", "sensor_data")
        assert pub.topic_name == "/rig/imu_a"
        got: list = []
        sub = node.create_subscription("sensor_msgs/msg/Imu", "/rig/imu_a", got.append,
                                       "sensor_data")
        assert spin_until(node, lambda: pub.get_subscription_count() == 1, HANG_S)
        node.destroy_subscription(sub)
        assert spin_until(node, lambda: pub.get_subscription_count() == 0, HANG_S)
        node.destroy_publisher(pub)
        assert spin_until(node, lambda: not node.get_publishers_info_by_topic("/rig/imu_a"), HANG_S)
    finally:
        node.destroy_node()


def test_the_graph_reads_only_what_changed(ros_domain: int,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """After a first full read, a new publisher costs the graph a read of its own instance only
    (not all 31 again) and a destroyed one a read of its vanished instance only; the answers
    still list exactly the publishers that exist. Counted by instance key, not by sample: a
    vanished instance goes through two states (disposed, then no writers), which a loaded
    machine's reads can catch one at a time (it once failed ``4 == 2`` counting samples)."""
    from cyclonedds.builtin import BuiltinDataReader

    node = create_node("counter", namespace="/frame", argv=["test"], backend="dds")
    try:
        pubs = [node.create_publisher("std_msgs/msg/Header", f"many_{i}", 10) for i in range(30)]

        def topics() -> set[str]:
            return {t for t, _ in node.get_topic_names_and_types() if "/many_" in t}

        assert spin_until(node, lambda: len(topics()) == 30, HANG_S)
        read = BuiltinDataReader.read
        counted: list[bytes] = []

        def counting(self: BuiltinDataReader, N: int = 1, condition: object = None) -> list:
            found = read(self, N, condition)
            counted.extend(sample.key.bytes for sample in found)
            return found

        monkeypatch.setattr(BuiltinDataReader, "read", counting)
        extra = node.create_publisher("std_msgs/msg/Header", "many_extra", 10)
        assert spin_until(node, lambda: "/frame/many_extra" in topics(), HANG_S)
        (new,) = set(counted)                       # the new one's instance, none of the 30
        assert len(counted) <= 2
        counted.clear()
        node.destroy_publisher(extra)
        node.destroy_publisher(pubs[0])
        assert spin_until(node, lambda: len(topics()) == 29, HANG_S)
        vanished = set(counted)
        assert len(vanished) == 2 and new in vanished   # the two that vanished, nothing else
        assert len(counted) <= 4                    # at most one read per state of each
        assert topics() == {f"/frame/many_{i}" for i in range(1, 30)}
    finally:
        node.destroy_node()


def test_message_helpers() -> None:
    assert messages.type_name("sensor_msgs/Imu") == "sensor_msgs/msg/Imu"
    js = messages.new("sensor_msgs/msg/JointState", name=["phi"], position=[1])
    assert js.position.dtype == float and js.position.tolist() == [1.0]
    assert messages.to_plain(js)["header"] == {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}
    stamp = messages.time_msg(3_000_000_007)
    assert (stamp.sec, stamp.nanosec) == (3, 7) and messages.stamp_ns(stamp) == 3_000_000_007
    back = messages.deserialize(messages.serialize(js), "sensor_msgs/msg/JointState")
    assert back.name == ["phi"] and back.position.tolist() == [1.0]


def test_logger_format_and_once(capsys: pytest.CaptureFixture[str]) -> None:
    log = Logger("frame.sim_node", level="info")
    assert log.info("started") is True
    assert log.debug("hidden") is False
    assert log.warning("bad sample", once=True) is True
    assert log.warning("bad sample", once=True) is False
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2
    assert re.fullmatch(r"\[INFO\] \[\d+\.\d{9}\] \[frame\.sim_node\]: started", lines[0])
    assert lines[1].startswith("[WARN] ")


def test_raw_subscription_gets_cdr_and_timestamps(ros_domain: int) -> None:
    node = create_node("raw", namespace="/frame", argv=["test"])
    try:
        got: list = []
        node.create_subscription("sensor_msgs/msg/JointState", "js",
                                 lambda data, info: got.append((data, info)), 10, raw=True)
        pub = node.create_publisher("sensor_msgs/msg/JointState", "js", 10)
        assert spin_until(node, lambda: pub.get_subscription_count() == 1, HANG_S)
        msg = messages.new("sensor_msgs/msg/JointState", name=["phi"], position=[0.25])
        before = time.time_ns()
        pub.publish(msg)
        after = time.time_ns()
        assert spin_until(node, lambda: got, HANG_S)
        data, info = got[0]
        cdr = bytes(messages.TYPESTORE.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
        assert data == cdr + b"\0" * (-len(cdr) % 4)
        assert before <= info.source_timestamp <= after <= info.received_timestamp
        pub.publish(data)  # CDR bytes are published as they are
        assert spin_until(node, lambda: len(got) == 2, HANG_S)
        assert got[1][0] == data
    finally:
        node.destroy_node()


def test_matched_counts_follow_endpoints_as_they_join(ros_domain: int) -> None:
    """The dds backend's matched counts (``cyclone_raw.matched_count``) equal the length of
    cyclonedds' own matched lists as readers join one by one (that list can raise IndexError
    when one joins between its two C calls; the count cannot)."""
    node = create_node("matched_counts")
    try:
        pub = node.create_publisher("std_msgs/msg/String", "/matched", "default")
        subs = []
        for joined in range(1, 4):
            subs.append(node.create_subscription("std_msgs/msg/String", "/matched",
                                                 lambda _m: None, "default"))
            assert spin_until(node, lambda j=joined: pub.get_subscription_count() == j, HANG_S)
            assert pub.get_subscription_count() == len(pub._writer.get_matched_subscriptions())
        assert all(s.get_publisher_count() == 1 for s in subs)
    finally:
        node.destroy_node()


def test_writer_guid_is_the_writers_own(ros_domain: int) -> None:
    """``cyclone_raw.writer_guid`` (the key only) equals cyclonedds' full matched-publication
    data and the writer's own GUID, for two writers in another participant; an unknown handle
    gives None."""
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    from stillframe.middleware import dds_types
    from stillframe.middleware.cyclone_raw import writer_guid

    node = create_node("guids", argv=["test"], backend="dds")
    try:
        sub = node.create_subscription("std_msgs/msg/Header", "/guids", lambda *_: None, 10,
                                       raw=True)
        other = DomainParticipant(ros_domain)
        topic = Topic(other, dds_types.dds_topic("/guids"),
                      dds_types.idl_struct("std_msgs/msg/Header"))
        writers = [DataWriter(other, topic) for _ in range(2)]
        assert spin_until(node, lambda: sub.get_publisher_count() == 2, HANG_S)
        reader = sub._reader
        handles = reader.get_matched_publications()
        assert {writer_guid(reader, h) for h in handles} == {w.guid.bytes for w in writers}
        assert all(writer_guid(reader, h) == reader.get_matched_publication_data(h).key.bytes
                   for h in handles)
        assert writer_guid(reader, 12345) is None
    finally:
        node.destroy_node()
