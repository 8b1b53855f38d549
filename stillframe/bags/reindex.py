"""Recover a bag whose recorder died or whose file was cut or damaged: ``stillframe bag reindex
DIR``.

A killed recorder leaves an MCAP file without its summary and footer, and no ``metadata.yaml``
(:mod:`stillframe.bags.storage`: both are written on close); a copy or a disk that ran out of
space leaves a file cut anywhere, inside a record, a chunk, the summary or the footer; a damaged
disk or copy flips bytes. Like ``ros2 bag reindex`` (and the Go ``mcap recover``, which is not on
PyPI) this keeps every message that is whole and intact in the file:

1. :func:`stillframe.bags.checked_mcap.check_mcap` reads the file front to back with every CRC
   checked: chunks whose CRC fails are skipped and counted; a damaged record length does not end
   the recovery (the chunks after it are found from the summary's index, or by their own CRC);
2. the record the cut fell in, if it is a chunk, is read with the ``mcap`` package's own
   :meth:`mcap.records.Chunk.read` (which returns the bytes there are), its compressed stream
   (none, zstd or lz4) decoded as far as it goes with a streaming decompressor, and the records
   inside it read with the package's ``StreamReader`` up to the last whole one.

The recovered schemas, channels and messages are written again with
:class:`stillframe.bags.storage.BagWriter` into a complete bag in DIR (the damaged file kept
beside it as ``*.damaged``), which ``ros2 bag``, rosbags and ``mcap`` read. Nothing is dropped
silently: messages whose channel or schema was lost, or whose type the typestore cannot learn
from the schema, are counted, and so are damaged chunks; and the result is never called complete
while the file's own summary counts more messages than were kept.
"""

from __future__ import annotations

import copy
import io
import shutil
import struct
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import lz4.frame
import yaml
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import MAGIC_SIZE, StreamReader
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import Typestore

from stillframe.bags.checked_mcap import check_mcap
from stillframe.bags.full_disk import RESERVE_NAME
from stillframe.bags.qos import qos_from_yaml
from stillframe.bags.storage import BagWriter
from stillframe.errors import BagError
from stillframe.files import directory, open_input

MAGIC = b"\x89MCAP0\r\n"
#: what reading a cut or damaged MCAP stream can raise (struct.error: a cut inside a field;
#: UnicodeDecodeError, a ValueError: a cut inside a string; CRC failures are ValueErrors)
READ_ERRORS = (McapError, struct.error, ValueError, EOFError, MemoryError)
#: opcode (1 byte) and record length (8 bytes) before every MCAP record
RECORD_PREFIX = 9


@dataclass
class Salvage:
    """What a checked read of a (possibly cut or damaged) MCAP file found."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    #: the file ended before its footer and closing magic
    truncated: bool = False
    #: messages read from the chunk the cut fell in
    from_partial_chunk: int = 0
    #: whole chunks skipped because their CRC, compression or records failed
    bad_chunks: int = 0
    #: the damage found besides a cut (:meth:`.checked_mcap.McapFile.problems`)
    problems: list[str] = field(default_factory=list)
    #: messages the file's own summary counts, when its summary is intact
    indexed: int | None = None


@dataclass(frozen=True)
class Recovered:
    """What reindexing kept: messages per topic, whether the file was cut short, what was
    dropped (by reason), the damage found, and what the file's own summary counted."""

    path: Path
    counts: dict[str, int]
    truncated: bool
    from_partial_chunk: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    indexed: int | None = None

    @property
    def total(self) -> int:
        """The messages recovered over every topic."""
        return sum(self.counts.values())

    @property
    def complete(self) -> bool:
        """Nothing lost: not cut, nothing damaged or dropped, every message the summary
        counts kept."""
        return not (self.truncated or self.dropped or self.problems) and (
            self.indexed is None or self.total >= self.indexed)

    @property
    def state(self) -> str:
        """One phrase: complete, cut short, or damaged."""
        if self.complete:
            return "complete"
        if not (self.dropped or self.problems) and (self.indexed is None
                                                    or self.total >= self.indexed):
            return "cut short; kept every whole message"
        return "damaged; kept the intact messages"


def _mcap_file(bag: Path) -> Path:
    directory(bag, what="bag directory", error=BagError)
    files = sorted(bag.glob("*.mcap"))
    if len(files) != 1:
        raise BagError(f"{bag}: expected one .mcap file to reindex, found {len(files)}")
    return files[0]


def _take(salvage: Salvage, record: object) -> None:
    if isinstance(record, Schema):
        salvage.schemas[record.id] = record
    elif isinstance(record, Channel):
        salvage.channels[record.id] = record
    elif isinstance(record, Message):
        salvage.messages.append(record)


def whole_records(stream: io.BufferedIOBase, *, skip_magic: bool = False) -> Iterator[object]:
    """The complete records of an MCAP stream, in order, chunks not broken up; stops quietly at
    the first record the stream does not hold whole."""
    try:
        yield from StreamReader(stream, skip_magic=skip_magic, emit_chunks=True,
                                validate_crcs=False).records
    except READ_ERRORS:
        return


def decoded_prefix(chunk: Chunk) -> bytes:
    """As much of a cut chunk's records as its compressed bytes give (no CRC: it is cut)."""
    if chunk.compression == "":
        return chunk.data
    if chunk.compression == "zstd":
        try:
            return zstandard.ZstdDecompressor().decompressobj().decompress(chunk.data)
        except zstandard.ZstdError:
            return b""
    if chunk.compression == "lz4":
        try:
            return lz4.frame.LZ4FrameDecompressor().decompress(chunk.data)
        except RuntimeError:
            return b""
    return b""


def _partial_chunk(tail: bytes) -> Chunk | None:
    """The chunk the file was cut in, from its bytes to the end of the file, or None."""
    if len(tail) < RECORD_PREFIX or tail[0] != Opcode.CHUNK:
        return None
    try:
        return Chunk.read(ReadDataStream(io.BytesIO(tail[RECORD_PREFIX:])))
    except READ_ERRORS:
        return None


def salvage(path: Path) -> Salvage:
    """Every intact schema, channel and message of the MCAP file at ``path`` (module
    docstring). A file that does not start as MCAP (beyond a cut inside the magic) is a
    :class:`BagError`."""
    with open_input(path, what="storage file (MCAP)", error=BagError) as stream:
        head = stream.read(MAGIC_SIZE)
    if not head or not MAGIC.startswith(head):
        raise BagError(f"{path}: not an MCAP file (its first bytes are not the MCAP magic)")
    if len(head) < MAGIC_SIZE:
        return Salvage(truncated=True)
    checked = check_mcap(path)
    found = Salvage(schemas=dict(checked.schemas), channels=dict(checked.channels),
                    truncated=not checked.complete, bad_chunks=len(checked.bad_chunks))
    found.messages = [Message(channel_id=cid, log_time=stamp, data=data, publish_time=stamp,
                              sequence=0) for cid, stamp, data in checked.messages()]
    found.problems = checked.problems(cut=False)
    if checked.statistics is not None and checked.summary_crc in ("ok", "absent"):
        found.indexed = checked.statistics.message_count
    if checked.cut_at is not None:
        with open_input(path, what="storage file (MCAP)", error=BagError) as stream:
            stream.seek(checked.cut_at)
            chunk = _partial_chunk(stream.read())
        if chunk is not None:
            before = len(found.messages)
            for record in whole_records(io.BytesIO(decoded_prefix(chunk)), skip_magic=True):
                _take(found, record)
            found.from_partial_chunk = len(found.messages) - before
    return found


def _learn_type(typestore: Typestore, schema: Schema) -> bool:
    """Teach ``typestore`` a ``ros2msg`` schema's type it lacks; False if it cannot."""
    if schema.name in typestore.fielddefs:
        return True
    if schema.encoding != "ros2msg":
        return False
    try:
        typestore.register(get_types_from_msg(schema.data.decode(), schema.name))
    except Exception:   # rosbags raises its own and plain errors for bad text
        return False
    return schema.name in typestore.fielddefs


def _qos(channel: Channel) -> list:
    """The channel's offered QoS; a damaged QoS text costs the QoS, not the topic."""
    try:
        items = yaml.safe_load(channel.metadata.get("offered_qos_profiles", "")) or []
        return qos_from_yaml(items if isinstance(items, list) else [], ValueError)
    except (yaml.YAMLError, ValueError):
        return []


def _unique(path: Path) -> Path:
    """``path`` or ``path.N``: never overwrite what an earlier reindex kept."""
    candidate, n = path, 0
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.name}.{n}")
    return candidate


def reindex(bag: str | Path, typestore: Typestore) -> Recovered:
    """Rewrite the bag at ``bag`` from every whole message in its MCAP file (module docstring).
    Types the typestore lacks are learnt from the bag's schemas on a copy of it."""
    bag = Path(bag)
    source = _mcap_file(bag)
    (bag / RESERVE_NAME).unlink(missing_ok=True)    # a killed recorder's reserve: room to work
    try:
        found = salvage(source)
    except OSError as exc:
        raise BagError(f"{source}: cannot read: {exc.strerror or exc}") from None
    store = typestore
    if any(s.name not in typestore.fielddefs for s in found.schemas.values()):
        store = copy.deepcopy(typestore)    # learn the bag's own types on a copy
    dropped: dict[str, int] = {}
    try:
        with tempfile.TemporaryDirectory(dir=bag.parent) as tmp:
            fresh = Path(tmp) / bag.name
            with BagWriter(fresh, store) as writer:
                topics: dict[int, str] = {}
                for channel in found.channels.values():
                    schema = found.schemas.get(channel.schema_id)
                    if schema is None or not _learn_type(store, schema) \
                            or channel.topic in topics.values():
                        continue
                    writer.add_topic(channel.topic, schema.name, _qos(channel))
                    topics[channel.id] = channel.topic
                for message in sorted(found.messages, key=lambda m: m.log_time):
                    if message.channel_id not in topics:
                        dropped["unknown_channel_or_type"] = \
                            dropped.get("unknown_channel_or_type", 0) + 1
                        continue
                    writer.write(topics[message.channel_id], message.log_time, message.data)
                counts = {topic: writer.count(topic) for topic in sorted(topics.values())}
            if found.bad_chunks:
                dropped["bad_chunks"] = found.bad_chunks
            source.rename(_unique(source.with_name(source.name + ".damaged")))
            (bag / "metadata.yaml").unlink(missing_ok=True)
            for item in fresh.iterdir():
                shutil.move(str(item), bag / item.name)
    except OSError as exc:
        raise BagError(f"{bag}: cannot write the reindexed bag: {exc.strerror or exc}") from None
    return Recovered(bag, counts, found.truncated, found.from_partial_chunk, dropped,
                     found.problems, found.indexed)


__all__ = ["READ_ERRORS", "Recovered", "Salvage", "decoded_prefix", "reindex", "salvage",
           "whole_records"]
