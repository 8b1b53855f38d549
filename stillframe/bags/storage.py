"""rosbag2 bags on disk: write, read and summarise (no middleware here).

A bag is a rosbag2 directory as ROS 2 Jazzy writes it: ``metadata.yaml`` version 9
(:mod:`stillframe.bags.metadata`) plus one MCAP file, so that ``ros2 bag info/play`` open our
bags and bags from ``ros2 bag record`` open here. Messages are kept as CDR bytes, exactly as
received.

Writing goes through the ``mcap`` package's public writer with the layout rosbag2's MCAP storage
plugin (``rosbag2_storage_mcap``) writes: profile ``ros2``, one ``ros2msg`` schema per type
(rosbags' ``generate_msgdef``), one ``cdr`` channel per topic with ``offered_qos_profiles`` and
``topic_type_hash`` in its metadata, uncompressed chunks, log time the receive time, and a
``rosbag2`` metadata record holding the bag's metadata. Unlike rosbag2's defaults (it turns chunk
CRCs off and leaves the data CRC off), every CRC is written: each chunk's, the data section's and
the summary's, so that a damaged byte is found (:mod:`stillframe.bags.checked_mcap`). The writer
keeps the open chunk (up to 1 MiB) in memory and writes the index, summary, footer and
``metadata.yaml`` only in :meth:`BagWriter.close`, which must therefore run on every exit path,
SIGINT/SIGTERM included (the recorder's shutdown path does that); a bag whose writer was killed
with SIGKILL has no footer and is recovered with ``stillframe bag reindex``.

Reading checks the bag: ``metadata.yaml`` field by field, and each MCAP file's CRCs and record
structure (:func:`open_bag`); messages come from the chunks that are intact, in log-time order,
and what is damaged is said (:attr:`BagReader.problems`). Bags of the sqlite3 storage (rosbag2's
default before Iron) have no checksums and are read with rosbags' ``AnyReader``.
"""

from __future__ import annotations

import copy
import heapq
import shutil
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path
from typing import Any

import yaml
from mcap.records import Channel, Schema
from mcap.writer import Writer
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Qos
from rosbags.rosbag2 import ReaderError
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import Typestore

from stillframe import __version__
from stillframe.bags.checked_mcap import McapFile, check_mcap
from stillframe.bags.full_disk import DiskLedger, Event, close_after_failure, mcap_writer
from stillframe.bags.metadata import (
    METADATA_FILE,
    BagMetadata,
    FileEntry,
    TopicEntry,
    dump_metadata,
    load_metadata,
)
from stillframe.bags.qos import qos_from_yaml, qos_to_yaml
from stillframe.errors import BagError, InputError
from stillframe.files import open_input

__all__ = ["BagConnection", "BagMessage", "BagReader", "BagSummary", "BagWriter", "TopicSummary",
           "bag_summary", "disagreements", "format_summary", "learn_types", "open_bag", "read_bag",
           "refuse_damage", "storage_files"]

#: the ROS distribution a bag's metadata names, as ``ros2 bag record`` on Jazzy writes it
ROS_DISTRO = "jazzy"
#: the MCAP header's profile for rosbag2 bags, and the name of the metadata record
PROFILE = "ros2"
METADATA_RECORD = "rosbag2"
LIBRARY = f"stillframe {__version__}; mcap {version('mcap')}"
#: what reading a damaged sqlite3 bag through rosbags can raise
_ROSBAGS_ERRORS = (AnyReaderError, ReaderError, OSError, KeyError, TypeError, ValueError)
SERVICE_EVENT_SUFFIX = "/_service_event"


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: ``stamp`` is the bag time stamp (ns since the epoch, receive time)."""

    topic: str
    type: str
    stamp: int
    data: bytes
    msg: Any = None


@dataclass(frozen=True)
class TopicSummary:
    """One topic of a bag as ``ros2 bag info`` lists it, plus its offered QoS and type hash."""

    name: str
    type: str
    count: int
    serialization_format: str
    type_description_hash: str
    offered_qos: list[Qos] = field(default_factory=list)


@dataclass(frozen=True)
class BagSummary:
    """What ``ros2 bag info`` shows about a bag (from ``metadata.yaml``, as rosbag2 does; times in
    ns since the epoch), and what checking the bag against its files found: ``problems``, one
    phrase each naming the file (damage, or the metadata disagreeing with the files)."""

    path: str
    files: list[str]
    size_bytes: int
    storage_id: str
    ros_distro: str
    start_ns: int
    duration_ns: int
    message_count: int
    topics: list[TopicSummary]
    problems: list[str] = field(default_factory=list)
    #: the metadata's ``custom_data`` (the recorder's losses are there)
    custom_data: dict[str, str] = field(default_factory=dict)

    @property
    def end_ns(self) -> int:
        """The time of the bag's last message [ns since the epoch]."""
        return self.start_ns + self.duration_ns

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary: ``end_ns`` added, QoS profiles as rosbag2 v9 writes them."""
        topics = [{"name": t.name, "type": t.type, "count": t.count,
                   "serialization_format": t.serialization_format,
                   "type_description_hash": t.type_description_hash,
                   "offered_qos_profiles": qos_to_yaml(t.offered_qos)} for t in self.topics]
        return {"path": self.path, "files": self.files, "size_bytes": self.size_bytes,
                "storage_id": self.storage_id, "ros_distro": self.ros_distro,
                "start_ns": self.start_ns, "duration_ns": self.duration_ns,
                "end_ns": self.end_ns, "message_count": self.message_count, "topics": topics,
                "custom_data": self.custom_data, "problems": self.problems}


@dataclass
class _Topic:
    channel: int
    type: str
    qos: list[Qos]
    hash: str


class BagWriter:
    """Write a rosbag2 bag (metadata v9, MCAP) from CDR bytes.

    Use as a context manager or call :meth:`close`: closing writes the index, the footer and
    ``metadata.yaml``; leaving the ``with`` block by an exception (KeyboardInterrupt included)
    still closes, so that every message written so far is kept. A write that fails (a full disk)
    ends the bag with what reached the file (:mod:`stillframe.bags.full_disk`).
    """

    def __init__(self, path: str | Path, typestore: Typestore) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise InputError(f"{self.path}: exists already, not overwriting (choose a new -o DIR)")
        try:
            self.path.mkdir(mode=0o755, parents=True)
        except OSError as exc:
            raise BagError(f"{self.path}: cannot create bag: {exc.strerror or exc}") from None
        self.file = self.path / f"{self.path.name}.mcap"
        self._typestore = typestore
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, int] = {}
        #: the events of the open chunk, in order (:data:`.full_disk.Event`)
        self._pending: list[Event] = []
        #: messages per channel, and their time range, in the complete chunks in the file
        self._counts: Counter[int] = Counter()
        self._times: list[int] = []
        #: the metadata's ``custom_data`` (set before closing)
        self.custom_data: dict[str, str] = {}
        self._closed = False
        try:
            self._ledger = DiskLedger(self.path, self.file)
            self._writer = mcap_writer(self._ledger)
            self._start(self._writer)
        except (BagError, OSError) as exc:
            shutil.rmtree(self.path, ignore_errors=True)     # nothing recorded: leave nothing
            if isinstance(exc, BagError):
                raise
            raise BagError(f"{self.path}: cannot create bag: {exc.strerror or exc}") from None
        self._ledger.settle()
        self._writers: dict[str, Callable[[int, bytes | memoryview], None]] = {}

    @staticmethod
    def _start(writer: Writer) -> None:
        writer.start(profile=PROFILE, library=LIBRARY)

    def add_topic(self, topic: str, msgtype: str, offered_qos: Sequence[Qos] = ()) -> None:
        """Declare a topic with its type and the QoS profiles its publishers offer.

        The message definition and its ``RIHS01_`` hash come from the typestore.
        """
        if topic in self._topics:
            raise InputError(f"{self.path}: topic {topic} added twice")
        if msgtype not in self._typestore.fielddefs:
            raise InputError(f"{self.path}: topic {topic}: unknown message type {msgtype!r}")
        if msgtype not in self._schemas:
            msgdef, _ = self._typestore.generate_msgdef(msgtype, ros_version=2)
            encoding = "ros2idl" if msgdef.startswith("=" * 80 + "\nIDL: ") else "ros2msg"
            schema = self._writer.register_schema(msgtype, encoding, msgdef.encode())
            self._schemas[msgtype] = schema
            self._pending.append(Schema(schema, msgtype, encoding, msgdef.encode()))
        rihs01 = self._typestore.hash_rihs01(msgtype)
        qos = list(offered_qos)
        metadata = {"offered_qos_profiles": yaml.safe_dump(qos_to_yaml(qos),
                                                           sort_keys=False).strip(),
                    "topic_type_hash": rihs01}
        channel = self._writer.register_channel(topic, "cdr", self._schemas[msgtype], metadata)
        self._pending.append(Channel(channel, topic, "cdr", metadata, self._schemas[msgtype]))
        self._topics[topic] = _Topic(channel, msgtype, qos, rihs01)

    def write(self, topic: str, stamp_ns: int, data: bytes | memoryview) -> None:
        """Append one message (CDR bytes) received at ``stamp_ns``."""
        if topic not in self._writers:
            self._writers[topic] = self.writer_of(topic)
        self._writers[topic](stamp_ns, data)

    def writer_of(self, topic: str) -> Callable[[int, bytes | memoryview], None]:
        """:meth:`write` for one topic, as short as it goes: ``write(stamp_ns, data)``, the
        recorder's per-message call: the event kept for the open chunk, the message given to
        the ``mcap`` writer, and the chunk's bookkeeping when the writer wrote it."""
        channel = self._topics[topic].channel
        add, keep, ledger = self._writer.add_message, self._pending.append, self._ledger

        def write(stamp_ns: int, data: bytes | memoryview) -> None:
            keep((channel, stamp_ns, data))
            try:
                add(channel, stamp_ns, data, stamp_ns)
            except OSError as exc:
                raise BagError(f"{self.file}: write failed: {exc.strerror or exc}") from None
            if ledger.wrote:
                self._settle()

        return write

    def _settle(self) -> None:
        """The open chunk reached the file: its messages counted as complete."""
        stamps = [e[1] for e in self._pending if isinstance(e, tuple)]
        self._counts.update(e[0] for e in self._pending if isinstance(e, tuple))
        if stamps:
            self._times = [min([*self._times, *stamps]), max([*self._times, *stamps])]
        self._pending.clear()
        self._ledger.settle()

    def count(self, topic: str) -> int:
        """Messages written on ``topic`` (the open chunk's included)."""
        channel = self._topics[topic].channel
        return self._counts[channel] + sum(1 for e in self._pending
                                           if isinstance(e, tuple) and e[0] == channel)

    def _metadata(self, extra: Sequence[Event] = ()) -> BagMetadata:
        """The bag's metadata over the complete chunks and the ``extra`` events."""
        counts = self._counts + Counter(e[0] for e in extra if isinstance(e, tuple))
        stamps = [*self._times, *(e[1] for e in extra if isinstance(e, tuple))]
        start, end = (min(stamps), max(stamps)) if stamps else (0, 0)
        total = sum(counts.values())
        return BagMetadata(
            version=9, storage_identifier="mcap", relative_file_paths=[self.file.name],
            starting_time_ns=start, duration_ns=end - start, message_count=total,
            topics=[TopicEntry(name, t.type, "cdr", t.qos, t.hash, counts[t.channel])
                    for name, t in self._topics.items()],
            files=[FileEntry(self.file.name, start, end - start, total)],
            custom_data=dict(self.custom_data), ros_distro=ROS_DISTRO)

    def _finish(self, writer: Writer, extra: list[Event]) -> None:
        """The metadata record, the summary and the footer."""
        writer.add_metadata(METADATA_RECORD, {"serialized_metadata": dump_metadata(
            self._metadata(extra), embedded=True)})
        writer.finish()

    def _write_metadata(self, extra: Sequence[Event] = ()) -> None:
        """``metadata.yaml``, written beside and moved (a reader never sees half of it)."""
        meta = self.path / METADATA_FILE
        fresh = meta.with_suffix(".yaml.tmp")
        try:
            fresh.write_text(dump_metadata(self._metadata(extra)))
            fresh.replace(meta)
        except OSError as exc:
            fresh.unlink(missing_ok=True)
            raise BagError(f"{meta}: cannot write it: {exc.strerror or exc}; the MCAP file is "
                           f"complete: free some space, then run `stillframe bag reindex "
                           f"{self.path}`") from None

    def close(self) -> None:
        """Write index, footer and ``metadata.yaml``; safe to call twice. After a write that
        failed (a full disk) the bag is closed with the chunks that reached the file
        (:mod:`stillframe.bags.full_disk`) and :class:`BagError` says what it holds."""
        if self._closed:
            return
        self._closed = True
        ledger = self._ledger
        failure: BaseException | None = ledger.failure
        if failure is None:
            ledger.release_reserve()
            try:
                self._writer.flush()
                if ledger.wrote:
                    self._settle()
                self._finish(self._writer, [])
                ledger.close()
                self._write_metadata()
                return
            except OSError as exc:
                failure = ledger.failure or exc
        reason = failure.strerror if isinstance(failure, OSError) and failure.strerror else (
            str(failure))
        pending = list(self._pending)
        received = sum(self._counts.values()) + sum(isinstance(e, tuple) for e in pending)
        salvaged = close_after_failure(ledger, self._start, pending, self._finish)
        if salvaged is not None:
            self._write_metadata(salvaged)
            kept = self._metadata(salvaged).message_count
            raise BagError(f"{self.path}: {reason}: recording stopped; the bag is closed with "
                           f"{kept} of the {received} messages received (the rest did not fit)")
        raise BagError(f"{self.path}: {reason}: recording stopped; "
                       f"{self.file.name} keeps {sum(self._counts.values())} of the {received} "
                       f"messages received in complete chunks but no index: free some space, "
                       f"then run `stillframe bag reindex {self.path}`")

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class BagConnection:
    """A topic of the storage files with the type its messages are stored as."""

    id: int
    topic: str
    msgtype: str


def learn_types(typestore: Typestore, schemas: Sequence[tuple[str, str, bytes]]) -> Typestore:
    """``typestore``, or a copy of it that also knows the ``(name, encoding, text)`` schemas'
    ``ros2msg`` types it lacks (a bag's own types; those it cannot learn stay unknown)."""
    missing = [(name, text) for name, encoding, text in schemas
               if name not in typestore.fielddefs and encoding == "ros2msg"]
    if not missing:
        return typestore
    store = copy.deepcopy(typestore)
    for name, text in missing:
        try:
            store.register(get_types_from_msg(text.decode(), name))
        except Exception:   # rosbags raises its own and plain errors for bad text
            continue
    return store


class BagReader:
    """An open bag (or a lone MCAP file): its topics, its messages from the intact chunks in
    log-time order, and :attr:`problems` (one phrase each, naming the file)."""

    def __init__(self, files: Sequence[McapFile], typestore: Typestore,
                 metadata: BagMetadata | None = None) -> None:
        self.metadata = metadata
        self.files = list(files)
        self.problems = [f"{f.path}: {p}" for f in self.files for p in f.problems()]
        self._channels: dict[tuple[int, int], BagConnection] = {}
        by_key: dict[tuple[str, str], BagConnection] = {}
        schemas = []
        for n, mcap in enumerate(self.files):
            for cid, channel in mcap.channels.items():
                schema = mcap.schemas.get(channel.schema_id)
                if schema is None:
                    self.problems.append(f"{mcap.path}: channel {channel.topic} has no schema")
                    continue
                schemas.append((schema.name, schema.encoding, schema.data))
                key = (channel.topic, schema.name)
                if key not in by_key:
                    by_key[key] = BagConnection(len(by_key), channel.topic, schema.name)
                self._channels[(n, cid)] = by_key[key]
            unknown = sum(count for cid, count in mcap.counts().items()
                          if (n, cid) not in self._channels)
            if unknown:
                self.problems.append(f"{mcap.path}: {unknown} messages on channels the file "
                                     "does not declare")
        self.connections = list(by_key.values())
        self._store = learn_types(typestore, schemas)

    def channel_qos(self) -> dict[str, list[Qos]]:
        """Each topic's offered QoS as its MCAP channel states it; BagError naming the file
        when that text is not rosbag2's form."""
        found: dict[str, list[Qos]] = {}
        for mcap in self.files:
            for channel in mcap.channels.values():
                text = channel.metadata.get("offered_qos_profiles", "")
                try:
                    items = yaml.safe_load(text) if text.strip() else []
                except yaml.YAMLError:
                    items = None
                if not isinstance(items, list | type(None)):
                    items = None
                if items is None:
                    raise BagError(f"{mcap.path}: unreadable bag file: channel {channel.topic}: "
                                   "offered_qos_profiles is not a YAML list")
                found[channel.topic] = qos_from_yaml(items, lambda msg, c=channel, m=mcap: (
                    BagError(f"{m.path}: unreadable bag file: channel {c.topic}: "
                             f"offered_qos_profiles{msg}")))
        return found

    def counts(self) -> Counter[BagConnection]:
        """Readable messages per connection."""
        total: Counter[BagConnection] = Counter()
        for n, mcap in enumerate(self.files):
            for cid, count in mcap.counts().items():
                if (n, cid) in self._channels:
                    total[self._channels[(n, cid)]] += count
        return total

    def time_range(self) -> tuple[int, int] | None:
        """``(first, last)`` message time over every storage file [ns], or None for a bag without
        messages."""
        ranges = [r for f in self.files if (r := f.time_range()) is not None]
        return (min(r[0] for r in ranges), max(r[1] for r in ranges)) if ranges else None

    def messages(self, connections: Sequence[BagConnection] = ()
                 ) -> Iterator[tuple[BagConnection, int, bytes]]:
        """``(connection, log time, data)`` of the readable messages of ``connections`` (all if
        empty), in log-time order across the files."""
        wanted = set(connections or self.connections)
        streams = []
        for n, mcap in enumerate(self.files):
            ids = {cid for (m, cid), c in self._channels.items() if m == n and c in wanted}
            if ids:
                streams.append(((log_time, n, self._channels[(n, cid)], data)
                                for cid, log_time, data in mcap.messages(ids)))
        for log_time, _, connection, data in heapq.merge(*streams, key=lambda m: (m[0], m[1])):
            yield connection, log_time, data

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        """The ``rosbags`` message of type ``msgtype`` from its CDR ``raw``, with the bag's own
        types."""
        return self._store.deserialize_cdr(raw, msgtype)


class _RosbagsReader:
    """A sqlite3 bag through rosbags' ``AnyReader``, with :class:`BagReader`'s interface (no
    checksums to check in that storage)."""

    def __init__(self, reader: AnyReader, metadata: BagMetadata) -> None:
        self.metadata = metadata
        self.problems: list[str] = []
        self._reader = reader
        self._by_id = {c.id: BagConnection(c.id, c.topic, c.msgtype) for c in reader.connections}
        self.connections = list(self._by_id.values())

    def messages(self, connections: Sequence[BagConnection] = ()
                 ) -> Iterator[tuple[BagConnection, int, bytes]]:
        ids = {c.id for c in connections or self.connections}
        try:
            for conn, stamp, data in self._reader.messages(
                    connections=[c for c in self._reader.connections if c.id in ids]):
                yield self._by_id[conn.id], stamp, bytes(data)
        except _ROSBAGS_ERRORS as exc:
            raise BagError(f"{self._reader.paths[0]}: corrupt message data: {exc}") from None

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        return self._reader.deserialize(raw, msgtype)

    def counts(self) -> Counter[BagConnection]:
        return Counter({self._by_id[c.id]: c.msgcount for c in self._reader.connections})

    def time_range(self) -> tuple[int, int] | None:
        if not self._reader.message_count:
            return None
        return self._reader.start_time, self._reader.end_time - 1


def storage_files(bag: Path, metadata: BagMetadata) -> list[Path]:
    """The storage files ``metadata.yaml`` lists, each a regular file of the bag directory
    (:func:`stillframe.files.open_input`: a FIFO would block a reader); BagError naming the
    first that is missing, of another kind, or lies elsewhere."""
    files = []
    for name in metadata.relative_file_paths:
        path = bag / name
        if Path(name).name != name or name in ("", ".", ".."):
            raise BagError(f"{bag / METADATA_FILE}: relative_file_paths: {name!r} is not a file "
                           "of the bag directory")
        if not path.exists():
            raise BagError(f"{path}: missing (metadata.yaml lists it)")
        open_input(path, what="bag storage file", error=BagError).close()
        files.append(path)
    if not files:
        raise BagError(f"{bag / METADATA_FILE}: relative_file_paths: lists no storage file")
    return files


@contextmanager
def open_bag(path: str | Path, default_typestore: Typestore) -> Iterator[BagReader]:
    """An open, checked reader of a rosbag2 directory (module docstring); a bag that cannot be
    read at all is a :class:`BagError` naming the file at fault."""
    bag = Path(path)
    metadata = load_metadata(bag)
    files = storage_files(bag, metadata)
    if metadata.storage_identifier == "mcap":
        yield BagReader([check_mcap(f) for f in files], default_typestore, metadata)
        return
    if metadata.storage_identifier != "sqlite3":
        raise BagError(f"{bag / METADATA_FILE}: storage_identifier: {metadata.storage_identifier!r}"
                       " is not a storage this reads (mcap, sqlite3)")
    reader = AnyReader([bag], default_typestore=default_typestore)
    try:
        reader.open()
    except _ROSBAGS_ERRORS as exc:
        raise BagError(f"{files[0]}: unreadable bag file: {exc}") from None
    try:
        yield _RosbagsReader(reader, metadata)
    finally:
        reader.close()


def refuse_damage(reader: BagReader | _RosbagsReader) -> None:
    """BagError listing what is damaged in the bag, if anything (for readers that need every
    message: identification, :func:`read_bag`)."""
    if reader.problems:
        raise BagError("; ".join(reader.problems) + " (`stillframe bag reindex` keeps what is "
                       "intact)")


def read_bag(path: str | Path, default_typestore: Typestore, *, topics: Sequence[str] = (),
             decode: bool = False) -> Iterator[BagMessage]:
    """Yield the messages of a bag in time-stamp order (only ``topics`` if given); a damaged
    bag is a :class:`BagError` before the first message.

    With ``decode`` each :class:`BagMessage` also carries the deserialised message; types come
    from the definitions stored in the bag, else from ``default_typestore``.
    """
    bag = Path(path)
    with open_bag(bag, default_typestore) as reader:
        refuse_damage(reader)
        connections = [c for c in reader.connections if not topics or c.topic in topics]
        if topics and (unknown := sorted(set(topics) - {c.topic for c in connections})):
            raise InputError(f"{bag}: no topic {', '.join(unknown)} in this bag")
        for conn, stamp, data in reader.messages(connections):
            try:
                msg = reader.deserialize(data, conn.msgtype) if decode else None
            except Exception as exc:    # rosbags raises struct, index, value errors
                raise BagError(f"{bag}: corrupt message data on {conn.topic} at {stamp} ns: "
                               f"{type(exc).__name__}") from None
            yield BagMessage(conn.topic, conn.msgtype, stamp, data, msg)


def disagreements(reader: BagReader | _RosbagsReader) -> list[str]:
    """Where ``metadata.yaml`` ("it") disagrees with the storage files ("they"): topics, types,
    counts, times, the files it lists; one phrase each."""
    meta = reader.metadata
    assert meta is not None
    found = []
    held = reader.counts()
    file_topics: dict[str, set[str]] = {}
    for connection in reader.connections:
        file_topics.setdefault(connection.topic, set()).add(connection.msgtype)
    for topic in meta.topics:
        types = file_topics.get(topic.name)
        count = sum(n for c, n in held.items() if c.topic == topic.name and c.msgtype == topic.type)
        if types is None:
            found.append(f"it lists {topic.name}, which they do not hold")
        elif topic.type not in types:
            found.append(f"it gives {topic.name} the type {topic.type}, they "
                         f"{', '.join(sorted(types))}")
        elif count != topic.message_count:
            found.append(f"{topic.name}: it counts {topic.message_count} messages, they hold "
                         f"{count} readable")
    listed = {t.name for t in meta.topics}
    found += [f"they hold {t}, which it does not list" for t in sorted(set(file_topics) - listed)]
    if (counted := sum(t.message_count for t in meta.topics)) != meta.message_count:
        found.append(f"its message_count {meta.message_count} is not the sum of its topics' "
                     f"counts ({counted})")
    if (total := sum(held.values())) != meta.message_count:
        found.append(f"message_count: it says {meta.message_count}, they hold {total} readable")
    if (span := reader.time_range()) is not None and (
            meta.starting_time_ns, meta.duration_ns) != (span[0], span[1] - span[0]):
        found.append(f"it spans {meta.starting_time_ns} + {meta.duration_ns} ns, the messages "
                     f"{span[0]} + {span[1] - span[0]} ns")
    if meta.files:
        names = [f.path for f in meta.files]
        if sorted(names) != sorted(meta.relative_file_paths):
            found.append(f"its files ({', '.join(names)}) are not its relative_file_paths "
                         f"({', '.join(meta.relative_file_paths)})")
        if (in_files := sum(f.message_count for f in meta.files)) != meta.message_count:
            found.append(f"its files count {in_files} messages, its message_count "
                         f"{meta.message_count}")
    return found


def bag_summary(path: str | Path, default_typestore: Typestore) -> BagSummary:
    """Everything ``ros2 bag info`` prints about a bag (from ``metadata.yaml``), and in
    ``problems`` what checking it against its storage files found."""
    bag = Path(path)
    with open_bag(bag, default_typestore) as reader:
        meta = reader.metadata
        assert meta is not None
        qos = reader.channel_qos() if isinstance(reader, BagReader) else {}
        problems = list(reader.problems)
        # against damaged files the counts disagree as a consequence: the damage is said
        if not problems and (differ := disagreements(reader)):
            problems.append(f"{bag / METADATA_FILE} disagrees with the storage files: "
                            + "; ".join(differ))
    topics = [TopicSummary(name=t.name, type=t.type, count=t.message_count,
                           serialization_format=t.serialization_format,
                           type_description_hash=t.type_description_hash,
                           offered_qos=t.offered_qos or qos.get(t.name, []))
              for t in sorted(meta.topics, key=lambda t: t.name)]
    return BagSummary(
        path=str(bag), files=list(meta.relative_file_paths),
        size_bytes=sum(p.stat().st_size for p in bag.iterdir() if p.is_file()),
        storage_id=meta.storage_identifier, ros_distro=meta.ros_distro or "unknown",
        start_ns=meta.starting_time_ns, duration_ns=meta.duration_ns,
        message_count=meta.message_count, topics=topics, problems=problems,
        custom_data=dict(meta.custom_data))


def _seconds(ns: int) -> str:
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def _time_point(ns: int) -> str:
    """``Jun 20 2024 10:27:25.402624468 (1718879245.402624468)`` in local time, as rosbag2."""
    local = time.localtime(ns // 1_000_000_000)
    day = f"{local.tm_mday:2d}"
    return (f"{time.strftime('%b', local)} {day} {time.strftime('%Y %H:%M:%S', local)}"
            f".{ns % 1_000_000_000:09d} ({_seconds(ns)})")


def _file_size(size: int) -> str:
    units = ["B", "KiB", "MiB", "GiB", "TiB"]
    value, index = float(size), 0
    while value >= 1024 and index < len(units) - 1:
        value /= 1024
        index += 1
    return f"{value:.{0 if index == 0 else 1}f} {units[index]}"


def format_summary(summary: BagSummary) -> str:
    """The text ``ros2 bag info`` (Jazzy) prints; service event topics listed as services."""
    indent = " " * 19

    def block(label: str, lines: list[str], indent: str = indent) -> list[str]:
        return [label + (lines[0] if lines else "")] + [indent + x for x in lines[1:]]

    topics = [t for t in summary.topics if not t.name.endswith(SERVICE_EVENT_SUFFIX)]
    services = [t for t in summary.topics if t.name.endswith(SERVICE_EVENT_SUFFIX)]
    out = [""]
    out += block("Files:             ", summary.files)
    out += [
        f"Bag size:          {_file_size(summary.size_bytes)}",
        f"Storage id:        {summary.storage_id}",
        f"ROS Distro:        {summary.ros_distro}",
        f"Duration:          {_seconds(summary.duration_ns)}s",
        f"Start:             {_time_point(summary.start_ns)}",
        f"End:               {_time_point(summary.end_ns)}",
        f"Messages:          {summary.message_count - sum(t.count for t in services)}",
    ]
    out += block("Topic information: ", [
        f"Topic: {t.name} | Type: {t.type} | Count: {t.count} | "
        f"Serialization Format: {t.serialization_format}" for t in topics])
    out.append(f"Service:           {len(services)}")
    out += block("Service information: ", [
        f"Service: {t.name.removesuffix(SERVICE_EVENT_SUFFIX)} | Type: "
        f"{t.type.removesuffix('_Event')} | Event Count: {t.count} | "
        f"Serialization Format: {t.serialization_format}" for t in services], indent + "  ")
    return "\n".join(out)
