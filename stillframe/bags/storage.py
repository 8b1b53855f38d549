"""rosbag2 bags on disk: write, read and summarise (no middleware here).

A bag is a rosbag2 directory as ROS 2 Jazzy writes it: ``metadata.yaml`` version 9 plus one MCAP
file, written and read with ``rosbags`` so that ``ros2 bag info/play`` open our bags and bags from
``ros2 bag record`` open here. Messages are kept as CDR bytes, exactly as received.

Why ``rosbags``'s writer (and not the ``mcap`` package): it writes the MCAP layout rosbag2 reads
(``ros2`` profile, ``ros2msg`` schemas, per-channel ``offered_qos_profiles``, the ``rosbag2``
metadata record) and ``metadata.yaml`` v9 with type hashes, in one place. It buffers the open
chunk (up to 1 MiB) in memory and writes the chunk index, summary, footer and ``metadata.yaml``
only in :meth:`BagWriter.close`; so :meth:`BagWriter.close` must run on every exit path, including
SIGINT/SIGTERM (the recorder's shutdown path does that). A bag whose writer was killed with SIGKILL
has no footer and reads as truncated.
"""

from __future__ import annotations

import contextlib
import re
import shutil
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import yaml
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection, ConnectionExtRosbag2, Qos
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.typesys.store import Typestore

from stillframe.bags.full_disk import DiskLedger
from stillframe.config.yamlio import load_yaml, problem
from stillframe.errors import BagError, InputError
from stillframe.files import directory, open_input, read_bytes

METADATA_VERSION = 9
#: the ROS distribution a bag's metadata names, as ``ros2 bag record`` on Jazzy writes it (rosbags
#: writes its own name there)
ROS_DISTRO = "jazzy"
#: What reading a damaged bag can raise (rosbags lets KeyError/TypeError through for
#: incomplete QoS records).
_BAG_ERRORS = (AnyReaderError, ReaderError, OSError, yaml.YAMLError, KeyError, TypeError,
               ValueError, RecursionError)
SERVICE_EVENT_SUFFIX = "/_service_event"
#: ``metadata.yaml``'s size at most: rosbag2 writes a few hundred bytes per topic and per
#: storage file, so a bag of a thousand of each stays under 1 MiB
MAX_METADATA_BYTES = 4 << 20


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
    """What ``ros2 bag info`` shows about a bag; times in ns since the epoch."""

    path: str
    files: list[str]
    size_bytes: int
    storage_id: str
    ros_distro: str
    start_ns: int
    duration_ns: int
    message_count: int
    topics: list[TopicSummary]

    @property
    def end_ns(self) -> int:
        return self.start_ns + self.duration_ns

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary: ``end_ns`` added, QoS profiles as rosbag2 v9 writes them."""
        topics = [{**{k: v for k, v in asdict(t).items() if k != "offered_qos"},
                   "offered_qos_profiles": dump_qos_v9(t.offered_qos)} for t in self.topics]
        return {**asdict(self), "end_ns": self.end_ns, "topics": topics}


def _name_distro(metadata: str) -> str:
    """rosbags's metadata text with :data:`ROS_DISTRO` as its ``ros_distro``."""
    return re.sub(r"^(\s*ros_distro:) rosbags$", rf"\1 {ROS_DISTRO}", metadata, count=1,
                  flags=re.MULTILINE)


class BagWriter:
    """Write a rosbag2 bag (metadata v9, MCAP) from CDR bytes.

    Use as a context manager or call :meth:`close`: closing writes the index, the footer and
    ``metadata.yaml``; leaving the ``with`` block by an exception (KeyboardInterrupt included)
    still closes, so that every message written so far is kept.
    """

    def __init__(self, path: str | Path, typestore: Typestore) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise InputError(f"{self.path}: exists already, not overwriting (choose a new -o DIR)")
        self._typestore = typestore
        self._writer = Writer(self.path, version=METADATA_VERSION,
                              storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except (OSError, WriterError) as exc:
            raise BagError(f"{self.path}: cannot create bag: {exc}") from None
        try:
            self._ledger = DiskLedger(self._writer, self.path)
        except BagError:
            self._writer.abort()
            shutil.rmtree(self.path, ignore_errors=True)    # nothing recorded: leave nothing
            raise
        # the metadata record in the MCAP file, then metadata.yaml, name the distro
        storage = self._writer.storage
        close_storage = storage.close
        storage.close = lambda version, text: close_storage(version, _name_distro(text))
        self._connections: dict[str, Connection] = {}

    def add_topic(self, topic: str, msgtype: str, offered_qos: Sequence[Qos] = ()) -> None:
        """Declare a topic with its type and the QoS profiles its publishers offer.

        The message definition and its ``RIHS01_`` hash come from the typestore.
        """
        if topic in self._connections:
            raise InputError(f"{self.path}: topic {topic} added twice")
        if msgtype not in self._typestore.fielddefs:
            raise InputError(f"{self.path}: topic {topic}: unknown message type {msgtype!r}")
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=self._typestore, offered_qos_profiles=list(offered_qos))

    def write(self, topic: str, stamp_ns: int, data: bytes | memoryview) -> None:
        """Append one message (CDR bytes) received at ``stamp_ns``."""
        self._writer.write(self._connections[topic], stamp_ns, data)

    def writer_of(self, topic: str) -> Callable[[int, bytes | memoryview], None]:
        """:meth:`write` for one topic, as short as it goes: ``write(stamp_ns, data)``, the
        recorder's per-message call (:meth:`.full_disk.DiskLedger.message_writer`)."""
        return self._ledger.message_writer(self._connections[topic].id)

    def count(self, topic: str) -> int:
        return self._writer.counts[self._connections[topic].id]

    def close(self) -> None:
        """Write index, footer and ``metadata.yaml``; safe to call twice. After a write that
        failed (a full disk) the bag is closed with the chunks that reached the file
        (:mod:`stillframe.bags.full_disk`) and :class:`BagError` says what it holds."""
        if self._writer.storage is None:
            return
        ledger = self._ledger
        failure = ledger.failure
        if failure is None:
            ledger.release_reserve()
            ledger.fold_times()
            try:
                self._writer.close()
                self._name_metadata_distro()
                return
            except (OSError, BagError) as exc:
                failure = ledger.failure or exc
        reason = failure.strerror if isinstance(failure, OSError) and failure.strerror else (
            str(failure))
        received = ledger.written + ledger.pending()
        if ledger.close_after_failure():
            self._name_metadata_distro()
            kept = sum(self._writer.counts.values())
            raise BagError(f"{self.path}: {reason}: recording stopped; the bag is closed with "
                           f"{kept} of the {received} messages received (the rest did not fit)")
        raise BagError(f"{self.path}: {reason}: recording stopped; "
                       f"{ledger.storage.path.name} keeps {ledger.written} of the {received} "
                       f"messages received in complete chunks but no index: free some space, "
                       f"then run `stillframe bag reindex {self.path}`")

    def _name_metadata_distro(self) -> None:
        """``metadata.yaml`` with :data:`ROS_DISTRO` (the MCAP metadata record has it already:
        the storage's ``close`` is wrapped); written beside and moved, so that a full disk
        leaves rosbags' own file in place."""
        meta = self.path / "metadata.yaml"
        fresh = meta.with_suffix(".yaml.distro")
        try:
            fresh.write_text(_name_distro(meta.read_text()))
            fresh.replace(meta)
        except OSError:
            fresh.unlink(missing_ok=True)

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _metadata(bag: Path) -> Any:
    """``metadata.yaml`` parsed: a regular file of at most :data:`MAX_METADATA_BYTES`, YAML
    whose aliases do not expand past the loader's bounds (:func:`load_yaml`)."""
    meta = bag / "metadata.yaml"
    raw = read_bytes(meta, what="bag metadata file", max_bytes=MAX_METADATA_BYTES,
                     error=BagError)
    try:
        return load_yaml(raw)
    except yaml.YAMLError as exc:
        raise BagError(f"{meta}: unreadable bag file: not valid YAML: {problem(exc)}") from None


def _storage_files(bag: Path) -> list[Path]:
    """The storage files that ``metadata.yaml`` lists (call after it has parsed)."""
    meta = _metadata(bag)["rosbag2_bagfile_information"]
    return [bag / Path(p).name for p in meta["relative_file_paths"]]


def _culprit(bag: Path) -> Path:
    """The file that makes a bag unreadable: the first storage file that does not open on its
    own, else ``metadata.yaml``."""
    try:
        files = _storage_files(bag)
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError, RecursionError):
        return bag / "metadata.yaml"
    for path in files:
        if not path.is_file():
            return path
        try:
            with Reader(path):
                pass
        except _BAG_ERRORS:
            return path
    return bag / "metadata.yaml"


def _first_line(exc: BaseException) -> str:
    if isinstance(exc, KeyError):
        return f"missing key {exc}"
    return next(iter(str(exc).splitlines()), type(exc).__name__)


def _check_dir(bag: Path) -> None:
    """Before rosbags reads them: the bag is a directory, its ``metadata.yaml`` is there and
    reads (:func:`_metadata`), and each storage file it lists that is there is a regular file
    (a FIFO would block the reader)."""
    directory(bag, what="bag directory", error=BagError)
    if not (bag / "metadata.yaml").exists():
        raise BagError(f"{bag / 'metadata.yaml'}: missing (not a rosbag2 directory?)")
    with contextlib.suppress(KeyError, TypeError):      # its contents: rosbags says what lacks
        for path in _storage_files(bag):
            if path.exists():
                open_input(path, what="bag storage file", error=BagError).close()


@contextmanager
def open_bag(path: str | Path, default_typestore: Typestore) -> Iterator[AnyReader]:
    """An open reader of a rosbag2 directory; an unreadable bag is an :class:`InputError` naming
    the file at fault."""
    bag = Path(path)
    _check_dir(bag)
    reader = AnyReader([bag], default_typestore=default_typestore)
    try:
        reader.open()
    except _BAG_ERRORS as exc:
        raise BagError(f"{_culprit(bag)}: unreadable bag file: {_first_line(exc)}") from None
    try:
        yield reader
    finally:
        reader.close()


def read_bag(path: str | Path, default_typestore: Typestore, *, topics: Sequence[str] = (),
             decode: bool = False) -> Iterator[BagMessage]:
    """Yield the messages of a bag in time-stamp order (only ``topics`` if given).

    With ``decode`` each :class:`BagMessage` also carries the deserialised message; types come
    from the definitions stored in the bag, else from ``default_typestore``.
    """
    bag = Path(path)
    with open_bag(bag, default_typestore) as reader:
        connections = [c for c in reader.connections if not topics or c.topic in topics]
        if topics and (unknown := sorted(set(topics) - {c.topic for c in connections})):
            raise InputError(f"{bag}: no topic {', '.join(unknown)} in this bag")
        try:
            for conn, stamp, data in reader.messages(connections=connections):
                msg = reader.deserialize(data, conn.msgtype) if decode else None
                yield BagMessage(conn.topic, conn.msgtype, stamp, bytes(data), msg)
        except _BAG_ERRORS as exc:
            files = ", ".join(str(p) for p in _storage_files(bag))
            raise BagError(f"{files}: corrupt message data: {_first_line(exc)}") from None


def _ext(conn: Connection) -> ConnectionExtRosbag2:
    assert isinstance(conn.ext, ConnectionExtRosbag2)
    return conn.ext


def bag_summary(path: str | Path, default_typestore: Typestore) -> BagSummary:
    """Everything ``ros2 bag info`` prints about a bag."""
    bag = Path(path)
    with open_bag(bag, default_typestore) as reader:
        count = reader.message_count
        start = reader.start_time if count else 0
        duration = reader.end_time - 1 - start if count else 0
        topics = [
            TopicSummary(
                name=c.topic, type=c.msgtype, count=c.msgcount,
                serialization_format=_ext(c).serialization_format,
                type_description_hash=c.digest,
                offered_qos=list(_ext(c).offered_qos_profiles),
            )
            for c in sorted(reader.connections, key=lambda c: c.topic)
        ]
        distro = reader.readers[0].ros_distro or "unknown"
        storage = _metadata(bag)["rosbag2_bagfile_information"]["storage_identifier"]
    return BagSummary(
        path=str(bag), files=[p.name for p in _storage_files(bag)],
        size_bytes=sum(p.stat().st_size for p in bag.iterdir() if p.is_file()),
        storage_id=storage, ros_distro=distro, start_ns=start, duration_ns=duration,
        message_count=count, topics=topics,
    )


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
