"""A bag on a filesystem that fills up: keep every chunk that reached the file, close the bag with
them, say so in one line.

The ``mcap`` package's writer (:class:`stillframe.bags.storage.BagWriter` drives it) touches the
disk only when it writes a full chunk and when it finishes (summary, footer); it writes through
:class:`DiskLedger`, the file-like object this module gives it. A write that fails with
``ENOSPC`` leaves a partial chunk in the file and the writer in a state it cannot go on from. The
ledger makes that end cleanly:

- it keeps the offset where the last chunk that was written completely ends (:attr:`durable_end`;
  the writer has then also written that chunk's message indexes);
- it holds a small *reserve* file (:data:`RESERVE_BYTES`) in the bag directory while recording
  and frees it when the bag closes, so that the summary and ``metadata.yaml`` find room on a full
  disk (a database's trick: space set aside before it is needed);
- on a failed write the bag is closed by :func:`close_after_failure`: the file is cut back to its
  complete chunks, and a fresh ``mcap`` writer is driven again with the same calls, chunk by
  chunk, from the records those chunks hold (read back with the ``mcap`` package's reader). A
  writer given the same calls writes the same bytes, so over the part of the file that is already
  there the replay writes nothing and only compares (a difference ends it); past it, it writes
  what the first writer could not: the chunk that failed, again as chunks of
  :data:`SALVAGE_CHUNK_BYTES` as far as they fit, then the summary and the footer. If the summary
  does not fit, the salvaged chunks are taken back one by one.

What is lost is what never reached the file whole: the part of the failed chunk that does not fit
and the messages received after. If even the summary does not fit, the file is cut back to its
complete chunks and ``stillframe bag reindex`` recovers them once there is room.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from mcap.exceptions import EndOfFile, McapError
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from stillframe.errors import BagError

#: room kept free for the summary, the footer and ``metadata.yaml`` while recording [bytes]
#: (the summary of a 1 GiB bag, 1000 chunks of 14 topics, takes about 150 KiB)
RESERVE_BYTES = 512 * 1024
RESERVE_NAME = ".reserve"
#: the chunk that failed is written again in chunks this small, as far as they fit [bytes]
SALVAGE_CHUNK_BYTES = 64 * 1024
#: room left for the summary, the footer and ``metadata.yaml`` when salvaging [bytes] (the
#: salvaged chunks are taken back one by one if that was too little)
SUMMARY_ROOM = 96 * 1024
#: the size of a chunk: the writer ends a chunk once its records take more [bytes]
CHUNK_BYTES = 2**20
#: a message record's bytes besides its data (opcode, length, channel, sequence, two times)
MESSAGE_OVERHEAD = 31
#: a chunk's open records in order, as the writer was given them: ``(channel id, log time,
#: data)`` for a message, a ``Schema`` or ``Channel`` record for a registration
Event = Any


class ReplayDivergedError(Exception):
    """A replay would write other bytes than the file holds."""


def mcap_writer(stream: Any) -> Writer:
    """The ``mcap`` package's writer as bags use it: uncompressed chunks of
    :data:`CHUNK_BYTES` (rosbag2's default: no compression), every CRC (each chunk's, the data
    section's, the summary's), every index and the statistics."""
    return Writer(stream, chunk_size=CHUNK_BYTES, compression=CompressionType.NONE,
                  enable_crcs=True, enable_data_crcs=True)


def replay(writer: Writer, events: Sequence[Event]) -> None:
    """Give ``writer`` the calls that made ``events`` (messages and registrations)."""
    for event in events:
        if isinstance(event, tuple):
            writer.add_message(event[0], event[1], event[2], event[1])
        elif isinstance(event, Schema):
            writer.register_schema(event.name, event.encoding, event.data)
        else:
            writer.register_channel(event.topic, event.message_encoding, event.schema_id,
                                    event.metadata)


def events_of(chunk: Chunk) -> list[Event]:
    """The records of a chunk read back, as :data:`Event`."""
    return [(r.channel_id, r.log_time, r.data) if isinstance(r, Message) else r
            for r in breakup_chunk(chunk, validate_crc=True) if isinstance(
                r, Message | Schema | Channel)]


class DiskLedger:
    """The stream the ``mcap`` writer writes to (``write``, ``tell``, ``flush``): the bag's
    file, its reserve, and what of the file is durable (module docstring)."""

    def __init__(self, bag: Path, path: Path) -> None:
        self.path = path
        self.reserve = bag / RESERVE_NAME
        #: the write that failed (None while the disk took every chunk)
        self.failure: OSError | None = None
        self.position = 0
        #: where the last complete chunk (and its message indexes) ends
        self.durable_end = 0
        #: set by every write, cleared by :meth:`settle`: the writer wrote a chunk
        self.wrote = False
        try:
            self.reserve.write_bytes(bytes(RESERVE_BYTES))
            self.file = path.open("xb", buffering=0)
        except OSError as exc:
            self.reserve.unlink(missing_ok=True)
            raise BagError(f"{bag}: cannot create bag: {exc.strerror or exc} (the bag keeps "
                           f"{RESERVE_BYTES // 1024} KiB free for its index)") from None

    def write(self, data: bytes | memoryview) -> int:
        """Write all of ``data`` and count it; after a failed write, refuse every later one with a
        :class:`~stillframe.errors.BagError` (the first failure is raised as its ``OSError``)."""
        if self.failure is not None:
            raise BagError(f"{self.path}: not written after a failed write")
        try:
            _write_all(self.file, data)
        except OSError as exc:
            self.failure = exc
            raise
        self.position += len(data)
        self.wrote = True
        return len(data)

    def tell(self) -> int:
        """The bytes written so far, the file position the MCAP writer records."""
        return self.position

    def flush(self) -> None:
        """Nothing to do: every write went to the file unbuffered."""

    def settle(self) -> None:
        """What was written so far is durable: complete chunks."""
        self.durable_end = self.position
        self.wrote = False

    def release_reserve(self) -> None:
        """Delete the reserve file, freeing its space for the bag's closing records."""
        self.reserve.unlink(missing_ok=True)

    def close(self) -> None:
        """Close the file; an error on close is ignored, since every write went to the file
        unbuffered and nothing is left to flush."""
        with contextlib.suppress(OSError):
            self.file.close()

    def room(self) -> int:
        """Bytes the filesystem of the bag still takes."""
        stats = os.statvfs(self.path)
        return stats.f_bavail * stats.f_frsize


def _write_all(file: Any, data: bytes | memoryview) -> None:
    view = memoryview(data)
    while view:
        written = file.write(view)
        view = view[written:]


class _ReplayStream:
    """Compares what a replaying writer writes with the file up to ``until``, writes the rest."""

    def __init__(self, path: Path, until: int) -> None:
        self.file = path.open("r+b", buffering=0)
        self.until = until
        self.position = 0

    def write(self, data: bytes | memoryview) -> int:
        size = len(data)
        head = max(0, min(size, self.until - self.position))
        if head:
            self.file.seek(self.position)
            if self.file.read(head) != bytes(data[:head]):
                raise ReplayDivergedError(f"byte {self.position}")
        if head < size:
            self.file.seek(self.position + head)
            _write_all(self.file, memoryview(data)[head:])
        self.position += size
        return size

    def tell(self) -> int:
        return self.position

    def flush(self) -> None:
        """Nothing to do: unbuffered."""


def _groups(events: Sequence[Event]) -> list[list[Event]]:
    """The failed chunk's events in groups of about :data:`SALVAGE_CHUNK_BYTES`."""
    groups: list[list[Event]] = [[]]
    size = 0
    for event in events:
        groups[-1].append(event)
        if isinstance(event, tuple):
            size += len(event[2]) + MESSAGE_OVERHEAD
            if size >= SALVAGE_CHUNK_BYTES:
                groups.append([])
                size = 0
    return [g for g in groups if any(isinstance(e, tuple) for e in g)]


def close_after_failure(ledger: DiskLedger, start: Callable[[Writer], None],
                        failed: Sequence[Event],
                        finish: Callable[[Writer, list[Event]], None]) -> list[Event] | None:
    """Close the bag whose write failed (module docstring): ``start(writer)`` starts a fresh
    writer as the first was, ``finish(writer, salvaged)`` writes what closes it given the
    events salvaged. The salvaged events (the bag is closed), or None (the file was left as its
    complete chunks)."""
    ledger.close()
    ledger.release_reserve()
    groups = _groups(failed)
    keep = len(groups)
    while True:
        with ledger.path.open("r+b") as stream:
            stream.truncate(ledger.durable_end)
        outcome = _attempt(ledger, start, groups[:keep], finish)
        if outcome is True:
            return [e for group in groups[:keep] for e in group]
        if outcome is None or keep == 0:
            break
        keep = min(keep - 1, outcome)
    with contextlib.suppress(OSError), ledger.path.open("r+b") as stream:
        stream.truncate(ledger.durable_end)
    return None


def _complete_chunks(path: Path) -> Iterator[Chunk]:
    """The chunks of a file cut back to its complete chunks (it has no footer: the reader's
    end-of-file after the last one is the end)."""
    with path.open("rb") as source:
        records = StreamReader(source, emit_chunks=True).records
        while True:
            try:
                record = next(records)
            except (StopIteration, EndOfFile):
                return
            if isinstance(record, Chunk):
                yield record


def _attempt(ledger: DiskLedger, start: Callable[[Writer], None], groups: list[list[Event]],
             finish: Callable[[Writer, list[Event]], None]) -> bool | int | None:
    """One replay with ``groups`` salvaged: True when the bag closed; else how many groups were
    written before a write failed (or there was no room for one more), or None when the replay
    cannot reproduce the file."""
    stream = _ReplayStream(ledger.path, ledger.durable_end)
    written = 0
    try:
        writer = mcap_writer(stream)
        start(writer)
        for chunk in _complete_chunks(ledger.path):
            replay(writer, events_of(chunk))
            writer.flush()
        for group in groups:
            size = sum(len(e[2]) + MESSAGE_OVERHEAD for e in group if isinstance(e, tuple))
            if ledger.room() < size + SUMMARY_ROOM:
                return written
            replay(writer, group)
            writer.flush()
            written += 1
        finish(writer, [e for group in groups for e in group])
    except OSError:
        return written
    except (ReplayDivergedError, McapError, ValueError):
        return None
    finally:
        stream.file.close()
    return True


__all__ = ["CHUNK_BYTES", "RESERVE_BYTES", "RESERVE_NAME", "DiskLedger", "Event",
           "close_after_failure", "events_of", "mcap_writer", "replay"]
