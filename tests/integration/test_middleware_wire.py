"""The dds backend on the wire, checked against ``rosbags`` and plain ``cyclonedds``.

The independent side is written here from the ROS 2 naming rules (``rt/`` + topic,
``pkg::msg::dds_::Type_``, USER_DATA strings, ``ros_discovery_info``), not through the
project's code: hand-written IDL structs, ``rosbags``' own serializer and type hash.
"""

# No "from __future__ import annotations": cyclonedds resolves the IDL struct annotations.

import dataclasses
import json

import numpy as np
import pytest
from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsParticipant,
    BuiltinTopicDcpsPublication,
)
from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.base import Nodetype

from cyclonedds._clayer import ddspy_take  # isort: skip
from stillframe.contract.topics import CONTRACT
from stillframe.middleware.api import create_node, spin_until
from stillframe.middleware.dds_types import idl_struct
from stillframe.middleware.discovery import cyclone_config
from tests.support.middleware import finish, start_python, wait_for_line
from tests.support.waits import HANG_S

STORE = get_typestore(Stores.ROS2_JAZZY)
ANY = SampleState.Any | ViewState.Any | InstanceState.Any
DTYPES = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8,
          "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32,
          "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
          "float32": np.float32, "float64": np.float64}


def filled(type_name: str, seed: int = 1) -> object:
    """A message with every field set to a distinct non-default value (odd string and
    sequence lengths, so that CDR alignment and padding are exercised)."""
    counter = iter(range(seed, 10_000))

    def value(desc: tuple) -> object:
        kind, detail = desc
        if kind == Nodetype.BASE:
            prim, n = detail[0], next(counter)
            if prim == "string":
                return "abcdefg"[: n % 7 + 1]
            if prim == "bool":
                return n % 2 == 1
            return DTYPES[prim](n % 100 + (0.25 if prim.startswith("float") else 0)).item()
        if kind == Nodetype.NAME:
            return build(detail)
        sub, size = detail
        length = size if kind == Nodetype.ARRAY else next(counter) % 3 + 1
        items = [value(sub) for _ in range(length)]
        if sub[0] == Nodetype.BASE and sub[1][0] in DTYPES:
            return np.array(items, dtype=DTYPES[sub[1][0]])
        return items

    def build(name: str) -> object:
        return STORE.types[name](**{f: value(d) for f, d in STORE.fielddefs[name][1]})

    return build(type_name)


def plain(obj: object) -> object:
    """Nested dicts/lists of a rosbags message or a cyclonedds struct, for comparison."""
    if hasattr(obj, "__msgtype__"):  # rosbags: its dataclass also holds the constants
        return {f: plain(getattr(obj, f)) for f, _ in STORE.fielddefs[obj.__msgtype__][1]}
    if dataclasses.is_dataclass(obj):
        return {f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, np.ndarray | list | tuple):
        return [plain(x) for x in obj]
    return obj


def dds_type_name(ros_type: str) -> str:
    pkg, _, name = ros_type.split("/")
    return f"{pkg}::msg::dds_::{name}_"


@pytest.mark.parametrize("ros_type", sorted({spec.type_name for spec in CONTRACT}))
def test_bytes_on_the_wire_are_rosbags_cdr(ros_domain: int, ros_type: str) -> None:
    """For every contract type: the sample a node writes is byte for byte rosbags' CDR (padded
    to 4 bytes as Cyclone stores samples), and cyclonedds' own decoder of the generated struct
    reads back every field value."""
    node = create_node("wire_check", namespace="/frame", argv=["test"])
    try:
        struct = idl_struct(ros_type)
        assert struct.__idl_typename__ == dds_type_name(ros_type)
        participant = DomainParticipant(ros_domain)
        reliable = Qos(Policy.Reliability.Reliable(10**8), Policy.History.KeepLast(10),
                       Policy.DataRepresentation(use_cdrv0_representation=True))
        reader = DataReader(participant, Topic(participant, "rt/frame/wire", struct), reliable)
        pub = node.create_publisher(ros_type, "wire", "default")
        assert spin_until(node, lambda: pub.get_subscription_count() > 0, HANG_S)
        msg = filled(ros_type)
        pub.publish(msg)
        samples: list = []
        assert spin_until(node, lambda: samples.extend(ddspy_take(reader._ref, ANY, 8)) or samples,
                          HANG_S)
        wire = bytes(samples[0][0])
        expected = bytes(STORE.serialize_cdr(msg, ros_type))
        assert wire[:4] == b"\x00\x01\x00\x00"  # CDR little endian, XCDR1
        assert wire == expected + b"\0" * (-len(expected) % 4)
        assert plain(struct.deserialize(wire)) == plain(msg)
    finally:
        node.destroy_node()


# -- an independent reader, hand-written from the ROS 2 conventions ------------------------------
@dataclasses.dataclass
class DdsTime(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclasses.dataclass
class DdsHeader(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: DdsTime
    frame_id: str


@dataclasses.dataclass
class DdsQuaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@dataclasses.dataclass
class DdsVector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclasses.dataclass
class DdsImu(IdlStruct, typename="sensor_msgs::msg::dds_::Imu_"):
    header: DdsHeader
    orientation: DdsQuaternion
    orientation_covariance: t.array[t.float64, 9]
    angular_velocity: DdsVector3
    angular_velocity_covariance: t.array[t.float64, 9]
    linear_acceleration: DdsVector3
    linear_acceleration_covariance: t.array[t.float64, 9]


@dataclasses.dataclass
class DdsGid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: t.array[t.uint8, 16]


@dataclasses.dataclass
class DdsNodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: t.bounded_str[256]
    node_name: t.bounded_str[256]
    reader_gid_seq: t.sequence[DdsGid]
    writer_gid_seq: t.sequence[DdsGid]


@dataclasses.dataclass
class DdsParticipantEntitiesInfo(
    IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
):
    gid: DdsGid
    node_entities_info_seq: t.sequence[DdsNodeEntitiesInfo]


IMU_NODE = """
import sys
from stillframe.contract import messages
from stillframe.middleware.api import create_node, spin
node = create_node("imu_pub", namespace="/frame")
pub = node.create_publisher("sensor_msgs/msg/Imu", "floor1/imu", "sensor_data")
k = [0]
def tick():
    k[0] += 1
    pub.publish(messages.new(
        "sensor_msgs/msg/Imu",
        header=messages.new("std_msgs/msg/Header", stamp=messages.time_msg(k[0] * 10**7),
                            frame_id="floor1"),
        orientation_covariance=[-1.0] + [0.0] * 8,
        linear_acceleration=messages.new("geometry_msgs/msg/Vector3", x=0.25 * k[0]),
        linear_acceleration_covariance=[1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6],
    ))
node.create_timer(0.02, tick)
print("ready", flush=True)
spin(node)
node.destroy_node()
"""


def alive(reader: BuiltinDataReader) -> list:
    mask = SampleState.Any | ViewState.Any | InstanceState.Alive
    return reader.read(N=1000, condition=ReadCondition(reader, mask))


def test_independent_reader_decodes_a_node_and_finds_it_in_ros_discovery_info(
    ros_domain: int,
) -> None:
    proc = start_python(IMU_NODE)
    domain = Domain(ros_domain, cyclone_config())
    participant = DomainParticipant(ros_domain)
    try:
        wait_for_line(proc, "ready")
        sensor_qos = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
        reader = DataReader(participant, Topic(participant, "rt/frame/floor1/imu", DdsImu),
                            sensor_qos)
        latched = Qos(Policy.Reliability.Reliable(10**8), Policy.History.KeepLast(10),
                      Policy.Durability.TransientLocal)
        discovery = DataReader(
            participant, Topic(participant, "ros_discovery_info", DdsParticipantEntitiesInfo),
            latched,
        )
        imu = next(reader.take_iter(timeout=15 * 10**9))
        k = imu.header.stamp.nanosec // 10**7 + imu.header.stamp.sec * 100
        assert imu.header.frame_id == "floor1"
        assert imu.linear_acceleration.x == pytest.approx(0.25 * k, abs=0)
        assert imu.orientation_covariance[0] == -1.0
        assert imu.linear_acceleration_covariance[4] == 1e-6

        publications = alive(BuiltinDataReader(participant, BuiltinTopicDcpsPublication))
        publications = [p for p in publications if p.topic_name == "rt/frame/floor1/imu"]
        assert len(publications) == 1
        publication = publications[0]
        assert publication.type_name == "sensor_msgs::msg::dds_::Imu_"
        typehash = STORE.hash_rihs01("sensor_msgs/msg/Imu")
        assert publication.qos[Policy.Userdata].data == f"typehash={typehash};".encode()
        assert publication.qos[Policy.Reliability] == Policy.Reliability.BestEffort
        assert publication.qos[Policy.History] == Policy.History.KeepLast(5)
        assert publication.qos[Policy.Durability] == Policy.Durability.Volatile

        participants = {p.key: p for p in alive(BuiltinDataReader(participant,
                                                                  BuiltinTopicDcpsParticipant))}
        node_participant = participants[publication.participant_key]
        assert node_participant.qos[Policy.Userdata].data == b"enclave=/;"

        infos = [s for s in discovery.take_iter(timeout=10**9)]
        info = next(i for i in reversed(infos)
                    if bytes(i.gid.data) == publication.participant_key.bytes)
        nodes = {(n.node_namespace, n.node_name): n for n in info.node_entities_info_seq}
        assert ("/frame", "imu_pub") in nodes
        writers = {bytes(g.data) for g in nodes["/frame", "imu_pub"].writer_gid_seq}
        assert publication.key.bytes in writers
    finally:
        proc.terminate()
        finish(proc)
        del participant, domain


#: messages the talker may send ahead of what the listener has taken: fewer than the default
#: QoS's keep-last 10, so no sample can be overwritten however late the listener takes them
WINDOW = 5

TALKER = f"""
from stillframe.contract import messages
from stillframe.middleware.api import create_node, spin_until
node = create_node("talker")
pub = node.create_publisher("sensor_msgs/msg/JointState", "chatter", "default")
taken = [-1]
node.create_subscription("std_msgs/msg/Int32", "chatter_taken",
                         lambda m: taken.__setitem__(0, max(taken[0], m.data)), "default")
assert spin_until(node, lambda: pub.get_subscription_count() > 0, {HANG_S}), "no listener"
sent = [0]
def tick():
    if sent[0] < 1000 and sent[0] - taken[0] <= {WINDOW}:
        pub.publish(messages.new("sensor_msgs/msg/JointState", name=["k"],
                                 position=[float(sent[0])]))
        sent[0] += 1
node.create_timer(0.005, tick)
spin_until(node, lambda: sent[0] >= 1000, {HANG_S})
print("acked", pub.wait_for_all_acked({HANG_S}), flush=True)
node.destroy_node()
"""

LISTENER = f"""
import json
from stillframe.contract import messages
from stillframe.middleware.api import create_node, spin_until
node = create_node("listener")
got = []
taken = node.create_publisher("std_msgs/msg/Int32", "chatter_taken", "default")
def report():
    if got:
        taken.publish(messages.new("std_msgs/msg/Int32", data=got[-1]))
def take(m):
    got.append(int(m.position[0]))
    report()
node.create_subscription("sensor_msgs/msg/JointState", "chatter", take, "default")
node.create_timer(0.05, report)     # again, for a talker whose reader matched late
print("ready", flush=True)
spin_until(node, lambda: len(got) >= 1000, {HANG_S})
print(json.dumps(got), flush=True)
node.destroy_node()
"""


def test_two_processes_exchange_1000_messages_with_default_qos(ros_domain: int) -> None:
    """A talker at up to 200 Hz (a sensor node's rate) and a listener, default QoS (reliable,
    keep last 10): every message arrives, in order. With keep-last 10 a reader that falls more
    than 10 samples behind loses samples, in ROS 2 as here, so the talker stays at most
    :data:`WINDOW` samples ahead of what the listener reports taken (its own topic, default QoS
    too): a loaded machine makes the exchange slower, never lossy."""
    listener = start_python(LISTENER)
    wait_for_line(listener, "ready")
    talker = start_python(TALKER)
    talker_out, talker_err = finish(talker)
    listener_out, _ = finish(listener)
    assert talker.returncode == 0, talker_err
    assert "acked True" in talker_out
    received = json.loads(listener_out.strip().splitlines()[-1])
    assert received == list(range(1000))
