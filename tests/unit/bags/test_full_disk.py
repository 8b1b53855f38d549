"""A bag written onto a filesystem that fills up (issue 31, item 2): one line (BagError, exit 3),
the bag closed with what reached the disk, read by two readers other than the writer (rosbags'
and the ``mcap`` package's non-seeking reader)."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
from mcap.stream_reader import StreamReader
from rosbags.highlevel import AnyReader

from stillframe.bags.full_disk import RESERVE_NAME
from stillframe.bags.storage import BagWriter
from stillframe.contract import messages
from stillframe.errors import BagError
from tests.support.tmpfs import small_tmpfs

TOPICS = ("/a", "/b")
#: the message's CDR: header, then a uint32 sequence number and padding (std_msgs/String)
PAYLOAD = 300


def cdr(n: int) -> bytes:
    return bytes(messages.serialize(messages.new("std_msgs/msg/String",
                                                 data=f"{n:010d}".ljust(PAYLOAD, "x"))))


def sequence(data: bytes) -> int:
    (length,) = struct.unpack_from("<I", data, 4)
    return int(data[8:8 + length - 1][:10])


def test_a_full_tmpfs_ends_the_bag_with_what_reached_the_disk(tmp_path: Path) -> None:
    with small_tmpfs(tmp_path / "fs", size_mib=8) as fs:
        bag = fs / "bag"
        sent = 0
        with pytest.raises(BagError) as failed, BagWriter(bag, messages.TYPESTORE) as writer:
            for topic in TOPICS:
                writer.add_topic(topic, "std_msgs/msg/String")
            writers = [writer.writer_of(topic) for topic in TOPICS]
            while sent < 10**6:       # 300 MB: far more than fits
                writers[sent % 2](sent, cdr(sent))
                sent += 1
        line = str(failed.value)
        assert "\n" not in line and "No space left on device" in line
        kept, received = (int(w) for w in line.split("closed with ")[1].split()[0:4:3])
        # what the writer was handed: every message sent, and the one whose write failed
        assert received == sent + 1
        assert kept >= 0.9 * received
        assert sorted(p.name for p in bag.iterdir()) == ["bag.mcap", "metadata.yaml"]
        assert not (bag / RESERVE_NAME).exists()
        with AnyReader([bag]) as reader:
            assert reader.message_count == kept
            assert sorted(c.topic for c in reader.connections) == list(TOPICS)
            read = [sequence(bytes(data)) for _, _, data in reader.messages()]
        # the messages kept are the first ones, each once, in order: nothing torn or skipped
        assert read == list(range(kept))
        with (bag / "bag.mcap").open("rb") as stream:
            records = list(StreamReader(stream, validate_crcs=True).records)
        assert sum(type(r).__name__ == "Message" for r in records) == kept
        assert type(records[-1]).__name__ == "Footer"


def test_a_disk_without_room_for_the_bag_refuses_it_in_one_line(tmp_path: Path) -> None:
    """Less room than the reserve: BagError before anything is recorded, nothing left behind
    (the record command then exits 3 before subscribing)."""
    with small_tmpfs(tmp_path / "fs", size_mib=1) as fs:
        (fs / "filler").write_bytes(bytes(768 * 1024))
        with pytest.raises(BagError) as refused:
            BagWriter(fs / "bag", messages.TYPESTORE)
        assert "\n" not in str(refused.value)
        assert "cannot create bag: No space left on device" in str(refused.value)
        assert not (fs / "bag").exists()
