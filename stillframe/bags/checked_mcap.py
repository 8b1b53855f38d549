"""An MCAP file read with its checksums checked: what it holds, what is damaged, and its messages
in log-time order without the damaged parts.

MCAP (https://mcap.dev/spec) protects a file with three CRC-32s, each optional (0: not written):
each chunk's CRC of its uncompressed records, the data section's CRC (``DataEnd``: every byte
from the start of the file to the ``DataEnd`` record) and the summary's CRC (``Footer``: the
summary section and the footer's fields before it). A CRC-32 detects every error within 32
consecutive bits, so one flipped byte anywhere in a file that carries all three is found.
:func:`check_mcap` reads the file once, front to back, record by record (opcode and length, then
the body, parsed with the ``mcap`` package's record classes), and checks each CRC the file has:

- a chunk whose CRC fails, or whose records do not parse, is *bad*: it is skipped and counted,
  with what its message index records said it held where they are readable;
- a record whose length runs past the end of the file (a length field flipped, or the file cut)
  ends the front-to-back walk there; the chunks after it are found again from the summary's chunk
  indexes when the summary's CRC holds, else by looking for the next chunk whose own CRC holds
  (a random match has odds of 2^-32), so that one damaged length does not cost the intact chunks
  after it;
- the summary is read only when its CRC holds (or it has none) and the footer is whole.

:class:`McapFile` then says what the file holds (schemas, channels, messages per channel and
their time range, counted from the chunks themselves), what the summary's statistics claim, and
every problem in one phrase each; :meth:`McapFile.messages` yields the messages of the good
chunks in log-time order (a merge over the chunks by their time ranges, as the ``mcap`` package's
seeking reader does). The file is memory-mapped, never read whole.
"""

from __future__ import annotations

import contextlib
import heapq
import io
import mmap
import struct
import zlib
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, ChunkIndex, Header, Metadata, Schema, Statistics

from stillframe.errors import BagError
from stillframe.files import open_input

MAGIC = b"\x89MCAP0\r\n"
#: opcode (1 byte) and record length (8 bytes) before every record
PREFIX = 9
_PREFIX = struct.Struct("<BQ")
#: a chunk's fixed fields: start and end time, uncompressed size, CRC, compression's length
_CHUNK = struct.Struct("<QQQII")
#: a message record's fields before its data: channel, sequence, log time, publish time
_MESSAGE = struct.Struct("<HIQQ")
_U64 = struct.Struct("<Q")
_U32 = struct.Struct("<I")
#: the footer record whole: prefix, summary start, summary offset start, summary CRC
_FOOTER = struct.Struct("<BQQQI")
FOOTER_BYTES = _FOOTER.size
#: what parsing a damaged record can raise
PARSE_ERRORS = (McapError, struct.error, ValueError, EOFError, MemoryError, IndexError)
COMPRESSIONS = ("", "zstd", "lz4")
_KNOWN = {int(op) for op in Opcode}


@dataclass
class ChunkInfo:
    """One chunk record of the file: where it is, what its header says, what it holds."""

    offset: int
    end: int
    #: the time range and compression its header states
    header_start_ns: int
    header_end_ns: int
    compression: str
    crc: int
    #: why it cannot be used ("" when it is good)
    fault: str = ""
    #: messages per channel: counted in the chunk when it is good, else what its message index
    #: records after it say (empty when they are unreadable too)
    counts: dict[int, int] = field(default_factory=dict)
    #: the log-time range of its messages (good chunks; the header's otherwise)
    start_ns: int = 0
    end_ns: int = 0

    @property
    def good(self) -> bool:
        """Whether the chunk passed every check (no fault recorded)."""
        return not self.fault


@dataclass
class McapFile:
    """What :func:`check_mcap` found in one MCAP file (module docstring)."""

    path: Path
    size: int
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    chunks: list[ChunkInfo] = field(default_factory=list)
    #: messages outside chunks (an unchunked file): (channel, log time, offset of the record)
    loose: list[tuple[int, int, int]] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    statistics: Statistics | None = None
    chunk_indexes: list[ChunkIndex] = field(default_factory=list)
    #: "ok", "fails", "absent" (the writer wrote 0) or "unchecked" (no DataEnd record reached)
    data_crc: str = "unchecked"
    #: "ok", "fails", "absent" (the writer wrote 0) or "missing" (no footer, or no summary)
    summary_crc: str = "missing"
    #: the file ends with its footer and magic
    complete: bool = False
    #: structural damage, one phrase each (bad chunks are in :attr:`chunks`)
    faults: list[str] = field(default_factory=list)
    #: how the file ends short of its footer (a cut), one phrase, else ""
    cut: str = ""
    #: the offset of the record a cut fell in, when it fell inside one
    cut_at: int | None = None

    @property
    def bad_chunks(self) -> list[ChunkInfo]:
        """The chunks that failed a check, in file order."""
        return [c for c in self.chunks if not c.good]

    @property
    def chunk_crcs(self) -> bool:
        """Whether every good chunk carries a CRC (our writer's; rosbag2's by default not)."""
        return all(c.crc for c in self.chunks)

    def counts(self) -> Counter[int]:
        """Messages per channel id in the good chunks and outside chunks."""
        total: Counter[int] = Counter()
        for chunk in self.chunks:
            if chunk.good:
                total.update(chunk.counts)
        total.update(cid for cid, _, _ in self.loose)
        return total

    def lost(self) -> Counter[int]:
        """Messages per channel id in the bad chunks, as far as their message indexes tell."""
        total: Counter[int] = Counter()
        for chunk in self.bad_chunks:
            total.update(chunk.counts)
        return total

    def time_range(self) -> tuple[int, int] | None:
        """The first and last log time of the messages that can be read (None: none)."""
        starts = [c.start_ns for c in self.chunks if c.good and c.counts]
        ends = [c.end_ns for c in self.chunks if c.good and c.counts]
        starts += [t for _, t, _ in self.loose]
        ends += [t for _, t, _ in self.loose]
        return (min(starts), max(ends)) if starts else None

    def problems(self, *, cut: bool = True) -> list[str]:
        """Every problem found, one phrase each: bad chunks, failed CRCs, damaged structure,
        and (with ``cut``) a file that ends short of its footer."""
        found = [self.cut] if cut and self.cut else []
        found += self.faults
        for chunk in self.bad_chunks:
            held = sum(chunk.counts.values())
            found.append(f"the chunk at byte {chunk.offset} {chunk.fault}: skipped"
                         + (f" ({held} messages by its index)" if held else ""))
        if self.data_crc == "fails":
            found.append("the data section's CRC fails")
        if self.summary_crc == "fails":
            found.append("the summary's CRC fails: its index is not used")
        return found

    def messages(self, channel_ids: set[int] | None = None
                 ) -> Iterator[tuple[int, int, bytes]]:
        """``(channel id, log time, data)`` of the readable messages (of ``channel_ids`` if
        given), in log-time order, file order among equal times."""
        wanted = (lambda cid: True) if channel_ids is None else channel_ids.__contains__
        with _mapped(self.path) as data:
            # (time, source, kind, index in source, item): a chunk (kind 0) goes in at its
            # first message's time and is replaced by its messages (kind 1) when it comes out;
            # a message outside chunks (kind 2) by the offset of its record
            queue: list[tuple[int, int, int, int, Any]] = [
                (chunk.start_ns, n, 0, 0, chunk) for n, chunk in enumerate(self.chunks)
                if chunk.good and any(wanted(cid) for cid in chunk.counts)]
            queue += [(stamp, len(self.chunks) + n, 2, 0, offset)
                      for n, (cid, stamp, offset) in enumerate(self.loose) if wanted(cid)]
            heapq.heapify(queue)
            while queue:
                _, source, kind, _, item = heapq.heappop(queue)
                if kind == 0:
                    for i, message in enumerate(_messages_in(_chunk_records(data, item))):
                        if wanted(message[0]):
                            heapq.heappush(queue, (message[1], source, 1, i, message))
                elif kind == 1:
                    yield item
                else:
                    yield _message(data, item + PREFIX, _record_end(data, item))


def _record_end(data: Any, at: int) -> int:
    return at + PREFIX + _U64.unpack_from(data, at + 1)[0]


def _message(data: Any, start: int, end: int) -> tuple[int, int, bytes]:
    cid, _, log_time, _ = _MESSAGE.unpack_from(data, start)
    return cid, log_time, bytes(data[start + _MESSAGE.size:end])


def _read(cls: Any, body: bytes | memoryview) -> Any:
    return cls.read(ReadDataStream(io.BytesIO(body)))


def _decompress(compression: str, raw: memoryview, size: int) -> bytes | memoryview:
    if compression == "":
        return raw
    if compression == "zstd":
        return zstandard.ZstdDecompressor().decompress(bytes(raw), max_output_size=size)
    if compression == "lz4":
        return lz4.frame.decompress(bytes(raw))
    raise ValueError(f"unknown compression {compression!r}")


def _chunk_layout(data: Any, at: int, size: int, end: int | None = None
                  ) -> tuple[ChunkInfo, memoryview]:
    """The chunk record at ``at``: its header, and its records still compressed, up to where
    its own records' length says (``end`` None: not its record length, which a flipped byte may
    have changed) or up to ``end`` (its record length, when its own is the damaged one);
    ``ChunkInfo.end`` is where its records end. ValueError (or struct.error) when the fields do
    not hold together."""
    view = memoryview(data)
    start_ns, end_ns, _, crc, name_length = _CHUNK.unpack_from(data, at + PREFIX)
    pos = at + PREFIX + _CHUNK.size
    if name_length > 4:
        raise ValueError("has a damaged header (compression)")
    compression = bytes(view[pos:pos + name_length]).decode("ascii", "replace")
    if compression not in COMPRESSIONS:
        raise ValueError(f"has an unknown compression {compression!r}")
    (length,) = _U64.unpack_from(data, pos + name_length)
    pos += name_length + 8
    stop = pos + length if end is None else end
    if stop > size or stop < pos:
        raise ValueError("runs past the end of the file")
    info = ChunkInfo(at, stop, start_ns, end_ns, compression, crc, start_ns=start_ns,
                     end_ns=end_ns)
    return info, view[pos:stop]


def _chunk_records(data: Any, chunk: ChunkInfo) -> bytes | memoryview:
    """A good chunk's records, decompressed (its CRC was checked by :func:`check_mcap`)."""
    _, raw = _chunk_layout(data, chunk.offset, len(data), chunk.end)
    size = _CHUNK.unpack_from(data, chunk.offset + PREFIX)[2]
    return bytes(_decompress(chunk.compression, raw, max(size, 1)))


def _messages_in(records: Any) -> Iterator[tuple[int, int, bytes]]:
    view = memoryview(records)
    pos, end = 0, len(view)
    while pos < end:
        opcode, length = _PREFIX.unpack_from(view, pos)
        stop = pos + PREFIX + length
        if opcode == Opcode.MESSAGE:
            cid, _, log_time, _ = _MESSAGE.unpack_from(view, pos + PREFIX)
            yield cid, log_time, bytes(view[pos + PREFIX + _MESSAGE.size:stop])
        pos = stop


def _scan_chunk(found: McapFile, chunk: ChunkInfo, records: Any) -> None:
    """Walk a chunk's records: schemas and channels taken, messages counted per channel with
    their time range. ValueError when a record runs past the chunk or does not parse."""
    view = memoryview(records)
    pos, end = 0, len(view)
    counts: Counter[int] = Counter()
    first, last = 2**64, -1
    schemas, channels = {}, {}
    while pos < end:
        if pos + PREFIX > end:
            raise ValueError("has a record cut short inside it")
        opcode, length = _PREFIX.unpack_from(view, pos)
        stop = pos + PREFIX + length
        if stop > end:
            raise ValueError("has a record that runs past its end")
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE.size:
                raise ValueError("has a message record too short for its fields")
            cid, _, log_time, _ = _MESSAGE.unpack_from(view, pos + PREFIX)
            counts[cid] += 1
            first, last = min(first, log_time), max(last, log_time)
        elif opcode == Opcode.SCHEMA:
            schema = _read(Schema, view[pos + PREFIX:stop])
            schemas[schema.id] = schema
        elif opcode == Opcode.CHANNEL:
            channel = _read(Channel, view[pos + PREFIX:stop])
            channels[channel.id] = channel
        pos = stop
    found.schemas.update(schemas)
    found.channels.update(channels)
    chunk.counts = dict(counts)
    if counts:
        chunk.start_ns, chunk.end_ns = first, last


def _checked(chunk: ChunkInfo, raw: memoryview, size: int) -> bytes | memoryview | None:
    """The chunk's records when its CRC holds, else None (no CRC, no decompression, another CRC)."""
    if not chunk.crc:
        return None
    try:
        records = _decompress(chunk.compression, raw, max(size, 1))
    except (*PARSE_ERRORS, zstandard.ZstdError, RuntimeError):
        return None
    return records if zlib.crc32(records) == chunk.crc else None


def _take_chunk(found: McapFile, data: Any, at: int, record_end: int, *,
                only_if_checked: bool = False) -> ChunkInfo | None:
    """Check and walk the chunk record at ``at``; its ``end`` is where the walk goes on.

    A chunk whose CRC holds is good whichever of its lengths agrees with it: by its records'
    own length field, or by its record length (:func:`_chunk_layout`); a damaged length, size
    or opcode around intact records costs a fault phrase, not the messages. With
    ``only_if_checked`` (a record whose opcode is not a chunk's, an offset found by search) it is
    taken only when its CRC holds, else None and nothing is recorded."""
    size = found.size
    layouts = []
    for end in (None, record_end):
        if end is not None and (end > size or any(c.end == end for c, _ in layouts)):
            continue
        try:
            layouts.append(_chunk_layout(data, at, size, end))
        except PARSE_ERRORS:
            continue
    stated = _CHUNK.unpack_from(data, at + PREFIX)[2] if at + PREFIX + _CHUNK.size <= size \
        else 0
    for chunk, raw in layouts:
        if (records := _checked(chunk, raw, stated)) is not None:
            break
    else:
        if only_if_checked:
            return None
        if not layouts:
            chunk = ChunkInfo(at, min(record_end, size), 0, 0, "", 0,
                              fault="has a damaged header")
            found.chunks.append(chunk)
            return chunk
        chunk, raw = layouts[0]
        try:
            records = _decompress(chunk.compression, raw, stated)
        except (*PARSE_ERRORS, zstandard.ZstdError, RuntimeError):
            chunk.fault = f"does not decompress ({chunk.compression or 'none'})"
        else:
            if chunk.crc:
                chunk.fault = "fails its CRC"
            elif len(records) != stated:
                chunk.fault = "holds another size than its header says"
        if not chunk.good:
            chunk.end = record_end if record_end <= size else chunk.end
            found.chunks.append(chunk)
            return chunk
    try:
        _scan_chunk(found, chunk, records)
    except PARSE_ERRORS as exc:
        chunk.fault = str(exc) if str(exc).startswith("has") else \
            "has a record that does not parse"
    if chunk.good and (chunk.end != record_end or len(records) != stated):
        found.faults.append(f"the chunk at byte {at} has a damaged length, size or opcode "
                            "(its records are whole and read)")
    found.chunks.append(chunk)
    return chunk


def _take_index(chunk: ChunkInfo | None, data: Any, at: int, end: int) -> None:
    """A message index record after a bad chunk: what the chunk held, by channel."""
    if chunk is None or chunk.good or end - at < PREFIX + 6:
        return
    cid = struct.unpack_from("<H", data, at + PREFIX)[0]
    (length,) = _U32.unpack_from(data, at + PREFIX + 2)
    if at + PREFIX + 6 + length == end and length % 16 == 0:
        chunk.counts[cid] = length // 16


def _resync(found: McapFile, data: Any, start: int) -> ChunkInfo | None:
    """The first chunk at or after ``start`` whose own CRC holds (taken), or None: where the
    walk goes on after damage."""
    def take(at: int) -> ChunkInfo | None:
        if at + PREFIX + _CHUNK.size > found.size:
            return None
        return _take_chunk(found, data, at, _record_end(data, at), only_if_checked=True)

    chunk, at = take(start), start
    while chunk is None and (at := data.find(b"\x06", at + 1)) != -1:
        chunk = take(at)
    return chunk


def _walk(found: McapFile, data: Any) -> int | None:
    """The data section front to back (module docstring); the offset of the ``DataEnd``
    record, or None when the walk did not reach one."""
    size = found.size
    at, last_chunk = len(MAGIC), None
    while at < size:
        if at + PREFIX > size:
            found.cut = f"the file ends inside a record's header at byte {at} (cut short?)"
            return None
        opcode, length = _PREFIX.unpack_from(data, at)
        end = at + PREFIX + length
        if opcode == Opcode.CHUNK:
            # past the end: taken only when its own fields and CRC say it is whole (its
            # record length was damaged), else the file was cut inside it
            chunk = _take_chunk(found, data, at, end, only_if_checked=end > size)
            if chunk is not None:
                last_chunk, at = chunk, chunk.end
                continue
        if end > size or (opcode not in _KNOWN and opcode < 0x80):
            what = ("runs past the end of the file" if end > size
                    else f"has an unknown opcode {opcode:#04x}")
            last_chunk = _resync(found, data, at)
            if last_chunk is None and end > size:
                found.cut, found.cut_at = f"the record at byte {at} {what} (cut short?)", at
                return None
            found.faults.append(f"the record at byte {at} {what}")
            if last_chunk is None:
                return None
            if last_chunk.offset != at:
                found.faults.append(f"the walk resumed at the chunk at byte "
                                    f"{last_chunk.offset}")
            at = last_chunk.end
            continue
        if opcode == Opcode.DATA_END:
            return at
        if opcode == Opcode.FOOTER:
            found.faults.append(f"a footer at byte {at} without a data end record before it")
            return None
        if opcode == Opcode.MESSAGE_INDEX:
            _take_index(last_chunk, data, at, end)
        else:
            _take_record(found, data, opcode, at, end)
        at = end
    found.cut = "the file ends before its data end record (cut short?)"
    return None


def _take_definition(found: McapFile, opcode: int, body: memoryview) -> None:
    """A schema or channel record outside chunks, taken unless its id is known already (the
    chunks' own, CRC-checked, come first); other records are passed over."""
    if opcode == Opcode.SCHEMA:
        schema = _read(Schema, body)
        found.schemas.setdefault(schema.id, schema)
    elif opcode == Opcode.CHANNEL:
        channel = _read(Channel, body)
        found.channels.setdefault(channel.id, channel)


def _take_record(found: McapFile, data: Any, opcode: int, at: int, end: int) -> None:
    """A record outside chunks: header, schema, channel, message, metadata."""
    body = memoryview(data)[at + PREFIX:end]
    try:
        if opcode == Opcode.HEADER:
            found.header = _read(Header, body)
        elif opcode == Opcode.MESSAGE:
            if end - at < PREFIX + _MESSAGE.size:
                raise ValueError("too short")
            cid, _, log_time, _ = _MESSAGE.unpack_from(data, at + PREFIX)
            found.loose.append((cid, log_time, at))
        elif opcode == Opcode.METADATA:
            record = _read(Metadata, body)
            found.metadata[record.name] = dict(record.metadata)
        else:
            _take_definition(found, opcode, body)
    except PARSE_ERRORS:
        name = Opcode(opcode).name.lower() if opcode in _KNOWN else f"{opcode:#04x}"
        found.faults.append(f"the {name} record at byte {at} does not parse")


def _read_summary(found: McapFile, data: Any) -> None:
    """The footer and, when its CRC holds (or it has none), the summary section."""
    size = found.size
    if size < len(MAGIC) * 2 + FOOTER_BYTES or bytes(data[size - len(MAGIC):]) != MAGIC:
        found.cut = found.cut or "the file does not end with its footer (cut short?)"
        return
    at = size - len(MAGIC) - FOOTER_BYTES
    opcode, length, start, _, crc = _FOOTER.unpack_from(data, at)
    if opcode != Opcode.FOOTER or length != FOOTER_BYTES - PREFIX:
        found.faults.append("the footer is damaged")
        return
    found.complete = True
    if start == 0:
        return
    if not len(MAGIC) <= start <= at:
        found.faults.append("the footer's summary offset points outside the file")
        found.summary_crc = "fails" if crc else found.summary_crc
        return
    if crc:
        if zlib.crc32(memoryview(data)[start:size - len(MAGIC) - 4]) != crc:
            found.summary_crc = "fails"
            return
        found.summary_crc = "ok"
    else:
        found.summary_crc = "absent"
    pos = start
    try:
        while pos < at:
            opcode, length = _PREFIX.unpack_from(data, pos)
            end = pos + PREFIX + length
            if end > at:
                raise ValueError("runs past the footer")
            body = memoryview(data)[pos + PREFIX:end]
            if opcode == Opcode.STATISTICS:
                found.statistics = _read(Statistics, body)
            elif opcode == Opcode.CHUNK_INDEX:
                found.chunk_indexes.append(_read(ChunkIndex, body))
            else:
                _take_definition(found, opcode, body)
            pos = end
    except PARSE_ERRORS:
        found.faults.append(f"the summary record at byte {pos} does not parse")
        found.statistics, found.chunk_indexes = None, []


def _indexed_chunks(found: McapFile, data: Any) -> None:
    """Chunks the summary's index knows of that the walk did not reach (it stopped at damage):
    read at their offsets (their own CRC decides)."""
    reached = {c.offset for c in found.chunks}
    for index in found.chunk_indexes:
        at = index.chunk_start_offset
        if at in reached:
            continue
        reached.add(at)
        if len(MAGIC) <= at <= found.size - PREFIX - _CHUNK.size and (_take_chunk(
                found, data, at, _record_end(data, at), only_if_checked=True) is not None):
            continue
        found.chunks.append(ChunkInfo(at, at, index.message_start_time, index.message_end_time,
                                      index.compression, 0, fault="is not where the summary's "
                                      "index says, or is damaged"))
    found.chunks.sort(key=lambda c: c.offset)


@contextmanager
def _mapped(path: Path) -> Iterator[Any]:
    with open_input(path, what="storage file (MCAP)", error=BagError) as stream:
        if stream.seek(0, io.SEEK_END) == 0:
            yield b""
            return
        data = mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            yield data
        finally:
            # a view of it still alive (an exception on its way): closed when it is collected
            with contextlib.suppress(BufferError):
                data.close()


def check_mcap(path: str | Path) -> McapFile:
    """Read and check the MCAP file at ``path`` (module docstring). A file that does not start
    with the MCAP magic, or cannot be read, is a :class:`BagError` naming it."""
    path = Path(path)
    try:
        with _mapped(path) as data:
            found = McapFile(path, len(data))
            if bytes(data[:len(MAGIC)]) != MAGIC:
                raise BagError(f"{path}: not an MCAP file (its first bytes are not the MCAP "
                               "magic)")
            data_end = _walk(found, data)
            if data_end is not None:
                (crc,) = _U32.unpack_from(data, data_end + PREFIX)
                if not crc:
                    found.data_crc = "absent"
                else:
                    found.data_crc = "ok" if zlib.crc32(
                        memoryview(data)[:data_end]) == crc else "fails"
            _read_summary(found, data)
            if found.complete and found.cut:    # a whole file: the walk was stopped by damage
                found.faults.insert(0, found.cut.removesuffix(" (cut short?)"))
                found.cut, found.cut_at = "", None
            if found.summary_crc in ("ok", "absent"):
                _indexed_chunks(found, data)
    except OSError as exc:
        raise BagError(f"{path}: cannot read: {exc.strerror or exc}") from None
    return found


__all__ = ["MAGIC", "ChunkInfo", "McapFile", "check_mcap"]
