"""A bag on a filesystem that fills up (issue 31): keep every chunk that reached the file, close
the bag with them, say so in one line.

rosbags' MCAP writer (:class:`stillframe.bags.storage.BagWriter` uses it) touches the disk only
when it writes a full chunk and when it closes (summary, footer, ``metadata.yaml``); a write that
fails with ``ENOSPC`` leaves a partial chunk in the file, and closing then fails again (no room
for the summary). :class:`DiskLedger` makes that end cleanly:

- it keeps the offset where the last chunk that was written and flushed completely ends, and that
  chunk's message counts and time range (what the summary and ``metadata.yaml`` must say);
- it holds a small *reserve* file (:data:`RESERVE_BYTES`) in the bag directory while recording
  and frees it when the bag closes, so that the summary and ``metadata.yaml`` find room on a full
  disk (a database's trick: space set aside before it is needed);
- on a failed write it cuts the file back to the end of the last complete chunk and closes the bag
  from there (:meth:`DiskLedger.close_after_failure`): first with the chunk that failed (it may
  fit once the reserve is free), then without it.

What is lost is what never reached the file whole: the chunk being written when the disk filled
(at most 1 MiB) and the messages received after. If even the summary does not fit, the file is
cut back to its complete chunks and ``stillframe bag reindex`` recovers them once there is room.
"""

from __future__ import annotations

import contextlib
import os
import struct
from collections import defaultdict
from collections.abc import Callable
from io import BytesIO
from pathlib import Path
from typing import Any

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
MESSAGE_OPCODE = 0x05
#: a Message record's header (MCAP specification): opcode, record length, channel id, sequence,
#: log time, publish time; the length counts the fields after it and the data
_MESSAGE = struct.Struct("<BQHIQQ")
_MESSAGE_FIELDS = 2 + 4 + 8 + 8
#: rosbags' chunk size: a chunk is written once it holds more
CHUNK_BYTES = 2**20
_NO_TIME = 2**63 - 1


class DiskLedger:
    """The durable part of a rosbags ``Writer``'s MCAP file (module docstring), and the
    recorder's per-message write into it (:meth:`message_writer`): the one place that works on
    rosbags' ``McapWriter`` from outside."""

    def __init__(self, writer: Any, bag: Path) -> None:
        self.writer = writer
        self.storage = writer.storage
        self.reserve = bag / RESERVE_NAME
        self.counts: dict[int, int] = defaultdict(int)
        self.start, self.end = _NO_TIME, 0
        #: the write that failed (None while the disk took every chunk)
        self.failure: OSError | None = None
        try:
            self.storage.bio.flush()
            self.reserve.write_bytes(bytes(RESERVE_BYTES))
        except OSError as exc:
            raise BagError(f"{bag}: cannot create bag: {exc.strerror or exc} (the bag keeps "
                           f"{RESERVE_BYTES // 1024} KiB free for its index)") from None
        self.durable_end = self.storage.bio.tell()
        # every chunk goes through the ledger (an instance attribute shadows the method)
        self.storage.close_chunk = self._close_chunk

    def _close_chunk(self) -> None:
        """rosbags' ``close_chunk``, flushed to the file; counted only when it got there."""
        storage, chunk = self.storage, self.storage.chunk
        if self.failure is not None:
            raise BagError(f"{storage.path}: not written after a failed write")
        indexed = len(storage.chunks)
        try:
            type(storage).close_chunk(storage)
            storage.bio.flush()
        except OSError as exc:
            self.failure = exc
            del storage.chunks[indexed:]
            storage.chunk = chunk       # kept for one more try once the reserve is free
            raise BagError(f"{storage.path}: write failed: {exc.strerror or exc}") from None
        self.durable_end = storage.bio.tell()
        for cid, msgs in chunk.msgs.items():
            self.counts[cid] += len(msgs)
        self.start = min(self.start, chunk.message_start_time)
        self.end = max(self.end, chunk.message_end_time)

    def message_writer(self, cid: int) -> Callable[[int, bytes | memoryview], None]:
        """``write(stamp_ns, cdr)`` on channel ``cid``: the MCAP Message record appended to the
        open chunk with one ``struct.pack``, the chunk's message index and the counts kept as
        rosbags' ``McapWriter.write`` keeps them (it builds a ``BytesIO`` and four integers'
        bytes per message: 3.1 times as long, measured in one run); the bag's time range is
        taken per chunk (:meth:`fold_times`), not per message."""
        storage, counts, stats = self.storage, self.writer.counts, self.storage.channel_stats
        pack = _MESSAGE.pack

        def write(stamp_ns: int, data: bytes | memoryview) -> None:
            chunk = storage.chunk
            bio = chunk.bio
            chunk.msgs[cid].append((stamp_ns, bio.tell()))
            if stamp_ns < chunk.message_start_time:
                chunk.message_start_time = stamp_ns
            if stamp_ns > chunk.message_end_time:
                chunk.message_end_time = stamp_ns
            bio.write(pack(MESSAGE_OPCODE, _MESSAGE_FIELDS + len(data), cid, 0, stamp_ns,
                           stamp_ns))
            bio.write(data)
            counts[cid] += 1
            stats[cid] += 1
            if bio.tell() > CHUNK_BYTES:
                storage.close_chunk()

        return write

    def fold_times(self) -> None:
        """The bag's time range (``metadata.yaml`` and the MCAP statistics) over the chunks
        written and the open one; before closing."""
        writer, storage, chunk = self.writer, self.storage, self.storage.chunk
        start = min(writer.min_timestamp, self.start, chunk.message_start_time)
        end = max(writer.max_timestamp, self.end, chunk.message_end_time)
        writer.min_timestamp, writer.max_timestamp = start, end
        storage.message_start_time, storage.message_end_time = start, end

    @property
    def written(self) -> int:
        """Messages in complete chunks in the file."""
        return sum(self.counts.values())

    def pending(self) -> int:
        """Messages in the chunk not yet in the file."""
        return sum(len(msgs) for msgs in self.storage.chunk.msgs.values())

    def release_reserve(self) -> None:
        self.reserve.unlink(missing_ok=True)

    def close_after_failure(self) -> bool:
        """Cut the file back to its complete chunks, write what fits of the chunk that failed
        as smaller chunks (:meth:`_salvage`), and close the bag, taking salvaged chunks back
        one by one while the summary does not fit. True if the bag is closed (summary, footer,
        ``metadata.yaml``); False if the file was left as its complete chunks."""
        self.release_reserve()
        failed = self.storage.chunk
        self._cut()
        states = self._salvage(failed)
        while True:
            if self._try_close():
                return True
            if not states:
                break
            self.durable_end, counts, self.start, self.end = states.pop()
            self.counts = defaultdict(int, counts)
            self._cut()
        self._cut()
        self.writer.storage = None
        with contextlib.suppress(OSError):
            self.storage.bio.close()
        self.writer.metapath.with_suffix(".yaml.tmp").unlink(missing_ok=True)
        return False

    def _try_close(self) -> bool:
        try:
            self.writer.close()
        except (OSError, BagError):
            return False
        return True

    def _salvage(self, failed: Any) -> list[tuple[int, dict[int, int], int, int]]:
        """The records of the chunk that failed, written again as chunks of
        :data:`SALVAGE_CHUNK_BYTES` while the filesystem has room for one more and
        :data:`SUMMARY_ROOM` beside it (the messages of a 1 MiB chunk are not all lost because
        the disk had room for half of them). The ledger's state before each chunk written, to
        take them back if the summary does not fit."""
        data, at = failed.bio.getvalue(), 0
        chunk = self.storage.chunk
        states = []
        while at < len(data):
            length = int.from_bytes(data[at + 1:at + 9], "little")
            record, opcode = data[at:at + 9 + length], data[at]
            at += 9 + length
            if opcode == MESSAGE_OPCODE:
                stamp = int.from_bytes(record[15:23], "little")
                chunk.msgs[int.from_bytes(record[9:11], "little")].append(
                    (stamp, chunk.bio.tell()))
                chunk.message_start_time = min(chunk.message_start_time, stamp)
                chunk.message_end_time = max(chunk.message_end_time, stamp)
            chunk.bio.write(record)
            if chunk.bio.tell() >= SALVAGE_CHUNK_BYTES or at >= len(data):
                if self._room() < chunk.bio.tell() + SUMMARY_ROOM:
                    break
                states.append((self.durable_end, dict(self.counts), self.start, self.end))
                try:
                    self._close_chunk()
                except BagError:
                    states.pop()
                    break
                chunk = self.storage.chunk
        self._cut()
        return states

    def _room(self) -> int:
        """Bytes the filesystem of the bag still takes."""
        stats = os.statvfs(self.storage.path)
        return stats.f_bavail * stats.f_frsize

    def _cut(self) -> None:
        """The file cut at the end of its last complete chunk and opened there again, an empty
        chunk pending; the summary's figures those of the complete chunks."""
        storage, writer = self.storage, self.writer
        with contextlib.suppress(OSError):
            storage.bio.close()     # its buffer may hold bytes the disk refused
        with storage.path.open("r+b") as stream:
            stream.truncate(self.durable_end)
        storage.bio = storage.path.open("ab")
        writer.storage = storage
        self.failure = None
        storage.chunk = type(storage.chunk)(_NO_TIME, 0, BytesIO(), defaultdict(list))
        counts = {cid: self.counts.get(cid, 0) for cid in storage.channel_stats}
        storage.channel_stats.update(counts)     # in place: the message writers hold them
        writer.counts.update(counts)
        storage.message_start_time, storage.message_end_time = self.start, self.end
        writer.min_timestamp, writer.max_timestamp = self.start, self.end
