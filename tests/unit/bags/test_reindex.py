"""``bag reindex`` on a bag cut anywhere: every whole message before the cut comes back.

A bag is cut at every 1/50 of its size and at random offsets (inside records, chunks, the
summary, the footer; uncompressed, zstd and lz4 chunks). Independent references for the number
of whole messages in each cut file:

- the ``mcap`` package's non-seeking reader (``StreamReader``) on the cut file, tolerating the
  cut, plus the same reader on the records of the chunk the cut fell in, decoded with a zstd
  library other than the one reindex uses (Python's ``compression.zstd`` / ``backports.zstd``);
- for uncompressed chunks, the intact file's own index: a message is whole in the cut file when
  its record ends at or before the cut (chunk offsets from the summary's chunk indexes, message
  offsets from the message index records).

The recovered bag then reads in ``rosbags``, and each topic holds the first messages of the
intact bag's, byte for byte.
"""

from __future__ import annotations

import io
import random
import shutil
from pathlib import Path

import lz4.frame
import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from rosbags.highlevel import AnyReader

from stillframe.app.cli import main
from stillframe.bags.reindex import reindex, salvage
from stillframe.contract.messages import TYPESTORE
from stillframe.errors import BagError
from stillframe.locations import REPO_ROOT

try:  # Python 3.14's module, else its backport (a rosbags dependency)
    from compression import zstd
except ImportError:  # pragma: no cover - below Python 3.14
    from backports import zstd

HAMMER = REPO_ROOT / "bags" / "hammer" / "hammer.mcap"
CUTS_PER_BAG = 50
RANDOM_CUTS = 20


def _rewrite(dest: Path, compression: CompressionType, chunk_size: int) -> Path:
    """The hammer bag's schemas, channels and messages written again by the ``mcap`` writer."""
    dest.mkdir()
    path = dest / f"{dest.name}.mcap"
    with HAMMER.open("rb") as src, path.open("wb") as out:
        reader = make_reader(src)
        writer = Writer(out, chunk_size=chunk_size, compression=compression)
        writer.start(profile="ros2", library="test")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                            schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id],
                    channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data,
                               message.publish_time, message.sequence)
        writer.finish()
    return dest


@pytest.fixture(scope="module", params=["hammer-as-recorded", "zstd-16k", "lz4-16k",
                                        "none-8k", "zstd-1024k", "lz4-1024k"])
def intact(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An intact bag directory: the sample bag as our recorder wrote it (one uncompressed
    chunk), or its messages in many small compressed or uncompressed chunks."""
    base = tmp_path_factory.mktemp(request.param)
    if request.param == "hammer-as-recorded":
        shutil.copytree(HAMMER.parent, base / "bag")
        return base / "bag"
    kind, size = request.param.split("-")
    compression = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                   "none": CompressionType.NONE}[kind]
    return _rewrite(base / "bag", compression, int(size.removesuffix("k")) * 1024)


def _mcap(bag: Path) -> Path:
    return next(bag.glob("*.mcap"))


def _independent_prefix(chunk: Chunk) -> bytes:
    """A cut chunk's records as far as its compressed bytes decode (other decoders than
    reindex's)."""
    if chunk.compression == "zstd":
        return zstd.ZstdDecompressor().decompress(chunk.data)
    if chunk.compression == "lz4":
        return lz4.frame.LZ4FrameDecompressor().decompress(chunk.data)
    return chunk.data


def _count_messages(stream: io.BytesIO, *, skip_magic: bool) -> tuple[int, int]:
    """Messages the mcap StreamReader yields before the cut, and the end of the last whole
    top-level record."""
    count, end = 0, 0 if skip_magic else 8
    reader = StreamReader(stream, skip_magic=skip_magic, emit_chunks=True)
    try:
        for record in reader.records:
            end = stream.tell()
            if isinstance(record, Chunk):
                count += _count_messages(io.BytesIO(_independent_prefix(record)),
                                         skip_magic=True)[0]
            count += isinstance(record, Message)
    except Exception:  # the reference tolerates whatever the cut raises
        pass
    return count, end


def stream_reader_count(data: bytes, chunk_starts: set[int]) -> int:
    """Whole messages of a cut MCAP file by the mcap package's StreamReader."""
    count, end = _count_messages(io.BytesIO(data), skip_magic=False)
    if end in chunk_starts and len(data) > end + 9:
        try:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(data[end + 9:])))
        except Exception:  # cut inside the chunk's header: nothing in it
            return count
        try:
            prefix = _independent_prefix(chunk)
        except Exception:  # cut before the first decodable block
            return count
        count += _count_messages(io.BytesIO(prefix), skip_magic=True)[0]
    return count


def index_ends(path: Path) -> list[int]:
    """The file offset where each message record of an uncompressed bag ends, from the intact
    file's chunk and message indexes."""
    data = path.read_bytes()
    ends = []
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    for index in summary.chunk_indexes:
        assert index.compression == ""
        records = index.chunk_start_offset + 9 + 8 + 8 + 8 + 4 + 4 + 8
        for offset in index.message_index_offsets.values():
            stream = ReadDataStream(io.BytesIO(data[offset + 9:]))
            stream.read2()      # channel id
            size = stream.read4()
            for _ in range(size // 16):
                stream.read8()  # log time
                at = records + stream.read8()
                length = int.from_bytes(data[at + 1:at + 9], "little")
                ends.append(at + 9 + length)
    return sorted(ends)


def chunk_starts(path: Path) -> set[int]:
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    return {index.chunk_start_offset for index in summary.chunk_indexes}


def cuts(size: int, seed: int, *, tail: bool) -> list[int]:
    """Every 1/50 of the size, random offsets, and with ``tail`` every 37th byte of the last
    3000 (the summary and the footer), in increasing order."""
    rng = random.Random(seed)
    return sorted({size * k // CUTS_PER_BAG for k in range(1, CUTS_PER_BAG)}
                  | {rng.randrange(1, size) for _ in range(RANDOM_CUTS)}
                  | set(range(size - 3000, size, 37) if tail else ())
                  | {size - 1, size - 8, size - 9})


def _topics(bag: Path) -> dict[str, list[bytes]]:
    found: dict[str, list[bytes]] = {}
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        for conn, _stamp, data in reader.messages():
            found.setdefault(conn.topic, []).append(bytes(data))
    return found


def _mcap_topics(path: Path) -> dict[str, list[bytes]]:
    found: dict[str, list[bytes]] = {}
    with path.open("rb") as stream:
        for _schema, channel, message in make_reader(stream).iter_messages(
                log_time_order=False):
            found.setdefault(channel.topic, []).append(message.data)
    return found


def test_every_cut_recovers_every_whole_message(intact: Path, tmp_path: Path) -> None:
    source = _mcap(intact)
    data = source.read_bytes()
    starts = chunk_starts(source)
    ends = index_ends(source) if "none" in intact.parent.name or "hammer" in intact.parent.name \
        else None
    original = _mcap_topics(source)
    total = sum(len(v) for v in original.values())
    previous = -1
    checked_in_rosbags = 0
    from_partial = 0
    for n, cut in enumerate(cuts(len(data), seed=len(data), tail="hammer" in intact.parent.name)):
        path = tmp_path / f"cut{cut}" / source.name
        path.parent.mkdir()
        path.write_bytes(data[:cut])
        found = salvage(path)
        expected = stream_reader_count(data[:cut], starts)
        assert len(found.messages) == expected, (cut, len(data))
        if ends is not None:
            assert expected == sum(end <= cut for end in ends), cut
        assert len(found.messages) >= previous, cut
        previous = len(found.messages)
        from_partial = max(from_partial, found.from_partial_chunk)
        assert found.truncated
        if n % 7 == 0 or cut >= len(data) - 9:
            result = reindex(path.parent, TYPESTORE)
            assert result.total == expected and result.truncated
            recovered = _topics(path.parent)
            for topic, messages in recovered.items():
                assert messages == original[topic][:len(messages)], (cut, topic)
            checked_in_rosbags += 1
    # cut in the summary or the footer: every message of the bag, none lost
    assert previous == total
    assert checked_in_rosbags >= 9
    if "16k" not in intact.parent.name:   # compressed blocks smaller than the chunk: partial
        assert from_partial > 0


def test_cut_in_the_middle_of_the_issue_bag_keeps_half() -> None:
    """The issue's case: the hammer bag cut at 50 % gave a struct.error and 0 messages."""
    data = HAMMER.read_bytes()
    ends = index_ends(HAMMER)
    half = len(data) // 2
    assert sum(end <= half for end in ends) > 0.4 * len(ends)


def test_intact_bag_is_not_truncated_and_keeps_everything(tmp_path: Path) -> None:
    bag = shutil.copytree(HAMMER.parent, tmp_path / "hammer")
    result = reindex(bag, TYPESTORE)
    assert not result.truncated and result.total == 1024 and result.dropped == {}
    # a second reindex never overwrites what the first one kept
    reindex(bag, TYPESTORE)
    assert sorted(p.name for p in bag.iterdir()) == [
        "hammer.mcap", "hammer.mcap.damaged", "hammer.mcap.damaged.1", "metadata.yaml"]


@pytest.mark.parametrize("content", [b"", b"\x89MC", b"not an mcap file at all",
                                     bytes(range(256)) * 4])
def test_empty_or_foreign_files_are_bag_errors_or_empty_bags(tmp_path: Path,
                                                             content: bytes) -> None:
    bag = tmp_path / "b"
    bag.mkdir()
    (bag / "b.mcap").write_bytes(content)
    if content and b"\x89MCAP0\r\n".startswith(content):
        assert reindex(bag, TYPESTORE).total == 0
    else:
        with pytest.raises(BagError, match="not an MCAP file"):
            reindex(bag, TYPESTORE)


def test_a_chunk_with_a_bad_crc_is_skipped_and_counted(tmp_path: Path) -> None:
    bag = _rewrite(tmp_path / "crc", CompressionType.NONE, 8 * 1024)
    path = _mcap(bag)
    data = bytearray(path.read_bytes())
    starts = sorted(chunk_starts(path))
    data[starts[1] + 200] ^= 0xFF          # inside the second chunk's records
    path.write_bytes(bytes(data[: starts[3]]))
    result = reindex(bag, TYPESTORE)
    assert result.dropped == {"bad_chunks": 1}
    assert result.total == len(salvage(next(bag.glob("*.damaged"))).messages)


def test_never_complete_while_the_summary_counts_more(tmp_path: Path) -> None:
    """The second chunk of an intact file overwritten with zeros (its record gone, the summary
    intact): reindex keeps the other chunks' messages, and says damaged with the summary's count,
    not complete; its exit code is 3."""
    bag = _rewrite(tmp_path / "zeros", CompressionType.NONE, 8 * 1024)
    path = _mcap(bag)
    data = bytearray(path.read_bytes())
    starts = sorted(chunk_starts(path))
    data[starts[1]:starts[2]] = bytes(starts[2] - starts[1])
    path.write_bytes(bytes(data))
    again = shutil.copytree(bag, tmp_path / "again")
    result = reindex(bag, TYPESTORE)
    assert main(["bag", "reindex", str(again)]) == BagError.exit_code
    total = sum(len(v) for v in _mcap_topics(HAMMER.parent / HAMMER.name).values())
    assert result.indexed == total == 1024
    assert 0 < result.total < total
    assert not result.complete and result.state.startswith("damaged")
    assert sum(len(v) for v in _topics(bag).values()) == result.total
