"""Every way stillframe writes a bag, read back by two libraries other than the writer's own
reading code: ``rosbags`` (``AnyReader``, what ``ros2 bag``-compatible tools use) and the ``mcap``
package (its seeking reader, and its stream reader with every CRC checked), message by message,
byte for byte.

The writing paths: :meth:`BagWriter.write` (reindex, tests), :meth:`BagWriter.writer_of` (the
recorder's per-message call), ``bag reindex`` of an intact bag and of a bag cut in its third
chunk (what a killed recorder leaves), and a bag closed on a full disk (the replay of
:mod:`stillframe.bags.full_disk`; needs a tmpfs, root only). The recorder process itself is read
this way in ``tests/integration/test_record_signals.py``. Each bag spans several 1 MiB chunks.
"""

from __future__ import annotations

import random
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap.records import Chunk, DataEnd, Footer
from mcap.stream_reader import StreamReader
from rosbags.highlevel import AnyReader

from stillframe.bags.reindex import reindex
from stillframe.bags.storage import BagWriter
from stillframe.contract.messages import TYPESTORE
from stillframe.errors import BagError
from tests.support.tmpfs import small_tmpfs

TOPICS = {"/frame/floor1/imu": "sensor_msgs/msg/Imu", "/chatter": "std_msgs/msg/String"}
T0 = 1_700_000_000_000_000_000
#: about 3.8 MB: four chunks
COUNT = 3200
Sent = list[tuple[str, int, bytes]]


def sent_messages(count: int = COUNT, seed: int = 5) -> Sent:
    """Messages of two topics (header-stamped IMU samples, strings of random length), every
    byte of each payload random beyond its CDR framing, in time order."""
    rng = random.Random(seed)
    out = []
    for k in range(count):
        stamp = T0 + k * 1_000_000
        if k % 2:
            text = "".join(rng.choice("abcdefgh") for _ in range(rng.randrange(0, 4000)))
            msg = TYPESTORE.types["std_msgs/msg/String"](data=text)
            out.append(("/chatter", stamp, bytes(TYPESTORE.serialize_cdr(msg,
                                                                         TOPICS["/chatter"]))))
        else:
            data = bytearray(TYPESTORE.serialize_cdr(TYPESTORE.types["sensor_msgs/msg/Imu"](
                header=TYPESTORE.types["std_msgs/msg/Header"](
                    stamp=TYPESTORE.types["builtin_interfaces/msg/Time"](
                        sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id="f"),
                orientation=TYPESTORE.types["geometry_msgs/msg/Quaternion"](x=0, y=0, z=0, w=1),
                orientation_covariance=np.zeros(9),
                angular_velocity=TYPESTORE.types["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=TYPESTORE.types["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                linear_acceleration_covariance=np.zeros(9)), TOPICS["/frame/floor1/imu"]))
            data[-72:] = rng.randbytes(72)     # the covariances: any bytes are a valid double
            out.append(("/frame/floor1/imu", stamp, bytes(data)))
    return out


def write_each(path: Path, sent: Sent) -> Path:
    with BagWriter(path, TYPESTORE) as bag:
        for topic, msgtype in TOPICS.items():
            bag.add_topic(topic, msgtype)
        for topic, stamp, data in sent:
            bag.write(topic, stamp, data)
    return path


def write_fast(path: Path, sent: Sent) -> Path:
    with BagWriter(path, TYPESTORE) as bag:
        for topic, msgtype in TOPICS.items():
            bag.add_topic(topic, msgtype)
        writers = {topic: bag.writer_of(topic) for topic in TOPICS}
        for topic, stamp, data in sent:
            writers[topic](stamp, memoryview(data))
    return path


def _mcap(bag: Path) -> Path:
    (path,) = bag.glob("*.mcap")
    return path


def reindexed_intact(path: Path, sent: Sent) -> Path:
    write_fast(path, sent)
    assert reindex(path, TYPESTORE).complete
    return path


def reindexed_cut(path: Path, sent: Sent) -> Path:
    """Cut in the third chunk and reindexed: the first two chunks' messages, and the whole
    records before the cut in the third (the expected list is shortened to match)."""
    write_fast(path, sent)
    data = _mcap(path).read_bytes()
    with _mcap(path).open("rb") as stream:
        starts = sorted(i.chunk_start_offset for i in make_reader(stream).get_summary()
                        .chunk_indexes)
    _mcap(path).write_bytes(data[:starts[2] + 300_000])
    (path / "metadata.yaml").unlink()
    result = reindex(path, TYPESTORE)
    assert result.truncated and not result.problems and result.from_partial_chunk > 0
    del sent[result.total:]
    return path


PATHS: dict[str, Callable[[Path, Sent], Path]] = {
    "write": write_each, "writer_of": write_fast, "reindex_intact": reindexed_intact,
    "reindex_cut": reindexed_cut}


def read_by_rosbags(bag: Path) -> Sent:
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        return [(c.topic, stamp, bytes(data)) for c, stamp, data in reader.messages()]


def read_by_mcap(bag: Path) -> Sent:
    with _mcap(bag).open("rb") as stream:
        return [(channel.topic, message.log_time, message.data) for _, channel, message
                in make_reader(stream, validate_crcs=True).iter_messages(log_time_order=True)]


def assert_checksums(bag: Path) -> None:
    """Every chunk carries its CRC, the data section and the summary theirs; the mcap
    package's stream reader checks the chunks and the data section, the summary's is computed
    here from the footer (``zlib``)."""
    data = _mcap(bag).read_bytes()
    with _mcap(bag).open("rb") as stream:
        records = list(StreamReader(stream, validate_crcs=True, emit_chunks=True).records)
    chunks = [r for r in records if isinstance(r, Chunk)]
    assert len(chunks) >= 2
    assert all(c.uncompressed_crc == zlib.crc32(c.data) != 0 for c in chunks)
    (end,) = [r for r in records if isinstance(r, DataEnd)]
    assert end.data_section_crc != 0
    footer = records[-1]
    assert isinstance(footer, Footer) and footer.summary_crc != 0
    assert zlib.crc32(data[footer.summary_start:len(data) - 8 - 4]) == footer.summary_crc
    assert struct.unpack_from("<I", data, len(data) - 12)[0] == footer.summary_crc


@pytest.mark.parametrize("path_kind", sorted(PATHS))
def test_rosbags_and_mcap_read_every_message_of_every_writing_path(tmp_path: Path,
                                                                   path_kind: str) -> None:
    sent = sent_messages()
    bag = PATHS[path_kind](tmp_path / "bag", sent)
    assert read_by_rosbags(bag) == sent
    assert read_by_mcap(bag) == sent
    assert_checksums(bag)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == len(sent)
    assert {t["topic_metadata"]["name"]: t["message_count"]
            for t in meta["topics_with_message_count"]} == {
        topic: sum(m[0] == topic for m in sent) for topic in TOPICS}


def test_a_bag_closed_on_a_full_disk_reads_in_both(tmp_path: Path) -> None:
    """The replayed close: the file's first part compared, not rewritten; the salvaged chunks
    and the summary appended. The messages kept are the first ones sent, byte for byte."""
    sent = sent_messages(count=20_000, seed=6)     # about 40 MB, more than the 8 MiB tmpfs
    with small_tmpfs(tmp_path / "fs", size_mib=8) as fs:
        with pytest.raises(BagError, match="the bag is closed with") as failed:
            write_fast(fs / "bag", sent)
        kept = int(str(failed.value).split("closed with ")[1].split()[0])
        assert kept > 0
        assert read_by_rosbags(fs / "bag") == sent[:kept]
        assert read_by_mcap(fs / "bag") == sent[:kept]
        assert_checksums(fs / "bag")
