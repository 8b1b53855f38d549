"""One flipped byte in a real bag we wrote, in every class of byte, is detected by every reader
of ours or changes nothing they read.

The bag (written by :class:`BagWriter`, four 1 MiB chunks) is taken apart here by a walk of its
own over the MCAP specification's record framing (opcode, length), independent of the readers'
code, into classes of bytes: record opcodes, record lengths, chunk headers, chunk bodies (the
records' framing and fields inside a chunk, schemas and channels), message data, the other
records of the data section (magic, header, message indexes, metadata, data end) and the summary
with the footer. In each class :data:`FLIPS` positions are drawn with a fixed seed and each is
flipped (xor with a random non-zero byte), one at a time. Every reader then either *detects* it
(a :class:`BagError`, or the problems it reports) or is *unaffected* (what it reads is
bit-identical to what it reads from the intact bag):

- ``bag info`` (:func:`bag_summary`): problems reported, or the same summary;
- ``play`` (the player's reading: :func:`bag_summary`'s problems, then :func:`open_bag`'s
  messages): problems, or the same messages, byte for byte;
- ``identify`` (:func:`read_series`): refused, or the same series;
- ``bag reindex``: a result that is not complete, or a complete bag with the same messages
  (read back by rosbags, another library than ours).

A flip in a record's length must not cost an intact message: there, reindex keeps every message
of the intact bag.
"""

from __future__ import annotations

import random
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from stillframe.bags.channels import Channel, read_series
from stillframe.bags.reindex import reindex
from stillframe.bags.storage import BagWriter, bag_summary, open_bag
from stillframe.contract.messages import TYPESTORE
from stillframe.errors import BagError
from tests.support.identify import imu_message, wrench_message

#: flips drawn per class of byte
FLIPS = 6
SEED = 38
DT_NS = 10_000_000
SAMPLES = 500
IMU, FORCE, TEXT = "/frame/floor1/imu", "/frame/excitation/wrench", "/log"
CHANNELS = [Channel(FORCE, "wrench.force.x"), Channel(IMU, "linear_acceleration.x")]
_PREFIX = struct.Struct("<BQ")


@pytest.fixture(scope="module")
def intact(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Identification's input and output at 100 Hz, and 4 kB strings beside them (so that
    the bag spans four chunks)."""
    rng = np.random.default_rng(SEED)
    bag = tmp_path_factory.mktemp("flips") / "bag"
    with BagWriter(bag, TYPESTORE) as writer:
        writer.add_topic(FORCE, "geometry_msgs/msg/WrenchStamped")
        writer.add_topic(IMU, "sensor_msgs/msg/Imu")
        writer.add_topic(TEXT, "std_msgs/msg/String")
        for k in range(SAMPLES):
            ns = 1_700_000_000 * 10**9 + k * DT_NS
            writer.write(FORCE, ns, TYPESTORE.serialize_cdr(wrench_message(
                ns, float(rng.standard_normal())), "geometry_msgs/msg/WrenchStamped"))
            writer.write(IMU, ns, TYPESTORE.serialize_cdr(
                imu_message(ns, float(rng.standard_normal())), "sensor_msgs/msg/Imu"))
            writer.write(TEXT, ns, TYPESTORE.serialize_cdr(TYPESTORE.types["std_msgs/msg/String"](
                data="".join(map(chr, rng.integers(97, 123, 4000)))), "std_msgs/msg/String"))
    return bag


def byte_classes(data: bytes) -> dict[str, list[int]]:
    """Byte offsets of each class (module docstring), from the record framing alone."""
    classes: dict[str, list[int]] = {k: [] for k in (
        "opcode", "record length", "chunk header", "chunk body", "message data",
        "other data records", "summary and footer")}
    classes["other data records"] += range(8)           # the magic
    at = 8
    while True:
        opcode, length = _PREFIX.unpack_from(data, at)
        classes["opcode"].append(at)
        classes["record length"] += range(at + 1, at + 9)
        body, end = at + 9, at + 9 + length
        if opcode == 0x06:   # chunk: start, end, size, crc, compression, records
            (name,) = struct.unpack_from("<I", data, body + 28)
            records = body + 32 + name + 8
            classes["chunk header"] += range(body, records)
            pos = records
            while pos < end:
                inner, size = _PREFIX.unpack_from(data, pos)
                if inner == 0x05:   # message: framing and fields, then the data
                    classes["chunk body"] += range(pos, pos + 9 + 22)
                    classes["message data"] += range(pos + 9 + 22, pos + 9 + size)
                else:
                    classes["chunk body"] += range(pos, pos + 9 + size)
                pos += 9 + size
        else:
            classes["other data records"] += range(body, end)
        at = end
        if opcode == 0x0F:      # data end: the summary and the footer follow
            break
    classes["summary and footer"] += range(at, len(data))
    return classes


def info_view(bag: Path) -> object:
    summary = bag_summary(bag, TYPESTORE)
    if summary.problems:
        return "detected"
    return {**summary.as_dict(), "size_bytes": None, "path": None}


def play_view(bag: Path) -> object:
    if bag_summary(bag, TYPESTORE).problems:
        return "detected"
    with open_bag(bag, TYPESTORE) as reader:
        if reader.problems:
            return "detected"
        return [(c.topic, stamp, data) for c, stamp, data in reader.messages()]


def identify_view(bag: Path) -> object:
    series = read_series(bag, CHANNELS)
    return [(s.channel, s.stamps_ns.tolist(), s.values.tolist()) for s in series]


def reindex_view(bag: Path) -> tuple[object, list | None]:
    """("detected", or the messages of the complete reindexed bag read by rosbags), and the
    messages of the reindexed bag in any case (None when reindex refused the file)."""
    try:
        result = reindex(bag, TYPESTORE)
    except BagError:
        return "detected", None
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        kept = [(c.topic, stamp, bytes(data)) for c, stamp, data in reader.messages()]
    return ("detected" if not result.complete else kept), kept


def view(reader: str, bag: Path) -> tuple[object, list | None]:
    """What ``reader`` makes of the bag ("detected" or what it read), and for reindex the
    messages it kept."""
    if reader == "reindex":
        return reindex_view(bag)
    try:
        return {"info": info_view, "play": play_view, "identify": identify_view}[reader](
            bag), None
    except BagError:
        return "detected", None


READERS = ("info", "play", "identify", "reindex")


def test_every_flip_is_detected_by_every_reader_or_changes_nothing(intact: Path,
                                                                   tmp_path: Path) -> None:
    (source,) = intact.glob("*.mcap")
    data = source.read_bytes()
    classes = byte_classes(data)
    assert all(len(v) >= FLIPS for v in classes.values()), {k: len(v) for k, v in classes.items()}
    expected = {reader: view(reader, shutil.copytree(intact, tmp_path / f"intact-{reader}"))[0]
                for reader in READERS}
    assert "detected" not in expected.values()
    everything = expected["reindex"]
    rng = random.Random(SEED)
    outcomes: dict[str, dict[str, int]] = {}
    for name, positions in classes.items():
        for at in rng.sample(positions, FLIPS):
            mask = rng.randrange(1, 256)
            for reader in READERS:
                bag = shutil.copytree(intact, tmp_path / f"{name}-{at}-{reader}".replace(" ", "_"))
                (bag / source.name).write_bytes(data[:at] + bytes([data[at] ^ mask])
                                                + data[at + 1:])
                got, kept = view(reader, bag)
                where = f"{reader}: a flip ^{mask:#04x} at byte {at} ({name})"
                assert got == "detected" or got == expected[reader], where
                kind = "detected" if got == "detected" else "unaffected"
                outcomes.setdefault(f"{name} / {reader}", {}).setdefault(kind, 0)
                outcomes[f"{name} / {reader}"][kind] += 1
                if name == "record length" and reader == "reindex":
                    assert kept == everything, where    # whatever the damaged length
                shutil.rmtree(bag)
    print({k: v for k, v in sorted(outcomes.items())})
