"""The fast CDR of the contract messages (stillframe.contract.fixed_cdr, the codecs' ``cdr`` and
``*_reader``) against rosbags' CDR serializer and deserializer, byte for byte."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from stillframe.config.scene import load_scene
from stillframe.contract import messages
from stillframe.contract.codecs import (
    SENSOR_TOPICS,
    CommandMessage,
    EstimateMessages,
    SensorMessages,
    command_reader,
    estimate_reader,
    sensor_reader,
    state_reader,
    wrench_reader,
)
from stillframe.contract.fixed_cdr import CdrLayout, FixedReader, FixedWriter
from stillframe.contract.signals import Command, Estimate, Sample
from stillframe.contract.topics import CONTRACT
from stillframe.locations import SCENES_DIR
from stillframe.middleware.cyclone_raw import pad4

SENSORS = load_scene(SCENES_DIR / "thesis_lqg.yaml").sensors


def rosbags_cdr(msg: Any) -> bytes:
    """What the dds backend wrote before: rosbags' CDR padded to 4 bytes."""
    return bytes(pad4(messages.serialize(msg)))


def populated(type_name: str) -> Any:
    """A message of ``type_name`` with two elements in every sequence and non-empty strings."""
    msg = messages.new(type_name)
    for field, (kind, detail) in messages.fielddefs(type_name):
        if kind.name == "NAME":
            setattr(msg, field, populated(detail))
        elif kind.name == "BASE" and detail[0] == "string":
            setattr(msg, field, f"{field}-x")
        elif kind.name == "SEQUENCE":
            sub = detail[0]
            if sub[0].name == "BASE" and sub[1][0] == "string":
                setattr(msg, field, ["a", "bcd"])
            elif sub[0].name == "BASE":
                setattr(msg, field, np.zeros(2, dtype=messages.NUMPY_DTYPES[sub[1][0]]))
            else:
                setattr(msg, field, [populated(sub[1]), populated(sub[1])])
    return msg


def set_path(msg: Any, path: str, value: Any) -> None:
    """Set the field at a dotted path with ``[i]`` list indices."""
    *parents, name = path.split(".")
    for part in parents:
        field, _, index = part.partition("[")
        msg = getattr(msg, field)
        if index:
            msg = msg[int(index[:-1])]
    current = getattr(msg, name)
    if isinstance(current, np.ndarray):
        current[:] = value
    else:
        setattr(msg, name, type(current)(value))


def random_values(code: str, count: int, rng: np.random.Generator) -> list[Any]:
    if code == "?":
        return [bool(v) for v in rng.integers(0, 2, count)]
    if code in "fd":
        return [float(np.float32(v)) if code == "f" else float(v) for v in rng.normal(size=count)]
    info = np.iinfo({"b": np.int8, "B": np.uint8, "h": np.int16, "H": np.uint16,
                     "i": np.int32, "I": np.uint32, "q": np.int64, "Q": np.uint64}[code])
    return [int(v) for v in rng.integers(info.min, info.max, count, endpoint=True)]


@pytest.mark.parametrize("type_name", sorted({spec.type_name for spec in CONTRACT}))
def test_every_numeric_field_of_every_contract_type_matches_rosbags(type_name: str) -> None:
    rng = np.random.default_rng(7)
    msg = populated(type_name)
    layout = CdrLayout(msg)
    paths = list(layout.fields)
    assert paths, type_name
    writer, reader = FixedWriter(msg, paths), FixedReader(msg, paths)
    for _ in range(5):
        values: list[Any] = []
        for path in paths:
            _, code, count = layout.fields[path]
            chunk = random_values(code, count, rng)
            set_path(msg, path, chunk if count > 1 else chunk[0])
            values += chunk
        data = bytes(writer.pack(*values))
        assert data == rosbags_cdr(msg)
        assert list(reader.unpack(data)) == pytest.approx(values, rel=0, abs=0)
        assert messages.to_plain(messages.deserialize(data, type_name)) == messages.to_plain(msg)


def test_fields_out_of_order_are_refused() -> None:
    with pytest.raises(ValueError, match="order"):
        FixedWriter(messages.new("geometry_msgs/msg/WrenchStamped"),
                    ("wrench.force.x", "header.stamp.sec"))


def samples(n: int) -> list[Sample]:
    rng = np.random.default_rng(3)
    return [Sample(k * 1e-3, rng.normal(size=4), float(rng.normal()), truth=rng.normal(size=8),
                   applied=None if k == 0 else rng.normal(size=2)) for k in range(n)]


def test_sensor_messages_cdr_equals_rosbags_of_filled_messages() -> None:
    out = SensorMessages(SENSORS)
    for k, sample in enumerate(samples(6)):
        ns = k * 1_000_000 + 2_999_999_999 * (k % 2)
        fast = [bytes(b) for b in out.cdr(sample, ns)]
        slow = [rosbags_cdr(m) for m in (*out.fill(sample, ns), out.fill_truth(sample, ns))]
        assert fast == slow


def test_estimate_and_command_cdr_equal_rosbags() -> None:
    rng = np.random.default_rng(4)
    out = EstimateMessages()
    commands = [CommandMessage(0), CommandMessage(1)]
    for k in range(5):
        cov = None if k == 0 else rng.normal(size=(8, 8))
        applied = None if k == 1 else rng.normal(size=2)
        estimate = Estimate(k * 1e-3, rng.normal(size=8), rng.normal(size=8), cov, applied)
        ns = k * 31_250_000
        cdr = [bytes(b) for b in out.cdr(estimate, ns)]
        assert cdr == [rosbags_cdr(m) for m in out.fill(estimate, ns)]
        # the estimate's reader: in place and through rosbags, the same values
        reader = estimate_reader()
        fast = reader.read(cdr[0])
        slow = reader._from_msg(messages.deserialize(cdr[0], reader.type_name))
        np.testing.assert_equal(fast, slow)
        assert fast[0] == ns and np.array_equal(fast[1], estimate.physical)
        np.testing.assert_array_equal(fast[2], np.full(2, np.nan) if applied is None else applied)
        command = Command(k * 1e-3, torque=float(rng.normal()), force=float(rng.normal()))
        for c in commands:
            assert bytes(c.cdr(command, ns)) == rosbags_cdr(c.fill(command, ns))


def test_readers_give_the_written_values_and_rosbags_decoding_agrees() -> None:
    out = SensorMessages(SENSORS)
    readers = [sensor_reader(ch, SENSORS) for ch in range(len(SENSOR_TOPICS))]
    for k, sample in enumerate(samples(4)):
        ns = 1_000_000_000 + k * 1_000_000
        cdrs = out.cdr(sample, ns)
        applied = np.zeros(2) if sample.applied is None else sample.applied
        for ch, reader in enumerate(readers):
            fast = reader.read(bytes(cdrs[ch]))
            slow = reader._from_msg(messages.deserialize(bytes(cdrs[ch]), reader.type_name))
            np.testing.assert_equal(fast, slow)
            value = sample.force if ch == 4 else sample.measurements[ch]
            assert fast[:2] == (ns, value)
            np.testing.assert_equal(fast[2], applied[0] if ch == 3 else np.nan)
        ns_read, truth = state_reader().read(bytes(cdrs[6]))
        assert ns_read == ns and np.array_equal(truth, sample.truth)
        assert wrench_reader("floor3", "wrench.force.x").read(bytes(cdrs[5])) == (ns, applied[1])
    command = Command(0.5, torque=0.25, force=-3.0)
    for actuator in (0, 1):
        data = bytes(CommandMessage(actuator).cdr(command, 500_000_000))
        assert command_reader(actuator).read(data) == (500_000_000, (0.25, -3.0)[actuator])


def test_other_layouts_are_decoded_by_rosbags_and_garbage_is_none() -> None:
    reader = sensor_reader(3, SENSORS)
    # another writer: two joints, the pendulum second, another frame id
    msg = messages.new("sensor_msgs/msg/JointState", name=["hinge", "pendulum"],
                       position=[9.0, 0.5], effort=[1.0, 2.0])
    msg.header.stamp.sec = 2
    data = messages.serialize(msg)
    assert reader._fixed.unpack(data) is None
    assert reader.read(data) == (2_000_000_000, 0.5, 2.0)
    # the same layout, another joint name of the same length: not the pendulum
    other = messages.new("sensor_msgs/msg/JointState", name=["pendulux"], position=[0.5],
                         effort=[1.0])
    other.header.frame_id = "pendulum"
    data = messages.serialize(other)
    assert reader._fixed.unpack(data) is None
    assert np.isnan(reader.read(data)[1])
    good = bytes(SensorMessages(SENSORS).cdr(samples(1)[0], 0)[3])
    assert reader.read(good[:-12]) is None
    assert reader.read(b"\x00\x01\x00\x00" + b"\xff" * 40) is None
    big_endian = b"\x00\x00" + good[2:]
    assert reader._fixed.unpack(big_endian) is None
    with_options = good[:2] + b"\x00\x03" + good[4:]     # padding count in the options
    assert reader.read(with_options) == reader.read(good)
