"""A bag's ``metadata.yaml``: read with every field checked, and written as ROS 2 Jazzy writes it.

The format is rosbag2's (``rosbag2_storage/yaml.hpp``): one mapping ``rosbag2_bagfile_information``
whose fields depend on its ``version`` (1 to 9): compression fields from 3, ``offered_qos_profiles``
as a YAML string from 4 and as a list of mappings from 9, ``files`` from 5, ``custom_data`` (a map
of strings, which ``ros2 bag info`` does not show) from 6, ``type_description_hash`` from 7,
``ros_distro`` from 8. rosbag2 reads counts and times as unsigned 64-bit integers and the rest as
strings, lists and maps, and refuses any other type.

:func:`load_metadata` checks each field against that: a field of the wrong type (a string, list,
map or null where a number belongs, a negative, huge or non-finite number, ...) is a
:class:`~stillframe.errors.BagError` naming ``metadata.yaml`` and the field's path, in one line.
:func:`dump_metadata` writes version 9, keys in rosbag2's order.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import Qos

from stillframe.bags.qos import qos_from_yaml, qos_to_yaml
from stillframe.config.yamlio import load_yaml, problem
from stillframe.errors import BagError
from stillframe.files import directory, read_bytes

METADATA_FILE = "metadata.yaml"
#: ``metadata.yaml``'s size at most: rosbag2 writes a few hundred bytes per topic and per
#: storage file, so a bag of a thousand of each stays under 1 MiB
MAX_METADATA_BYTES = 4 << 20
ROOT_KEY = "rosbag2_bagfile_information"
#: the version written, and the newest read (ROS 2 Jazzy's)
METADATA_VERSION = 9
#: rosbag2 reads counts and times as uint64; Python's int64 bound keeps them exact everywhere
#: (numpy, MCAP's uint64 fields read back as signed by some tools)
MAX_INT = 2**63 - 1


@dataclass(frozen=True)
class TopicEntry:
    """One topic of ``topics_with_message_count``."""

    name: str
    type: str
    serialization_format: str
    offered_qos: list[Qos]
    type_description_hash: str
    message_count: int


@dataclass(frozen=True)
class FileEntry:
    """One storage file of ``files`` (version 5 on)."""

    path: str
    starting_time_ns: int
    duration_ns: int
    message_count: int


@dataclass(frozen=True)
class BagMetadata:
    """What ``metadata.yaml`` says about a bag (times in ns since the epoch)."""

    version: int
    storage_identifier: str
    relative_file_paths: list[str]
    starting_time_ns: int
    duration_ns: int
    message_count: int
    topics: list[TopicEntry]
    compression_format: str = ""
    compression_mode: str = ""
    files: list[FileEntry] = field(default_factory=list)
    custom_data: dict[str, str] = field(default_factory=dict)
    ros_distro: str = ""


class _Fields:
    """Typed access to one mapping of the metadata; every failure names the field's path."""

    def __init__(self, source: Path, node: Any, path: str) -> None:
        self.source, self.path = source, path
        if not isinstance(node, dict):
            self.fail(path or "the document", "a mapping", node)
        self.node = node

    def fail(self, path: str, expected: str, value: Any) -> None:
        shown = repr(value)
        shown = shown if len(shown) <= 40 else shown[:37] + "..."
        raise BagError(f"{self.source}: {path}: expected {expected}, got "
                       f"{shown if value is not None else 'null'}")

    def get(self, key: str, check: Callable[[str, Any], Any]) -> Any:
        if key not in self.node:
            raise BagError(f"{self.source}: {self.path or 'the document'}: missing key {key!r}")
        return check(f"{self.path}.{key}" if self.path else key, self.node[key])

    def count(self, path: str, value: Any) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_INT:
            self.fail(path, f"an integer from 0 to {MAX_INT}", value)
        return value

    def text(self, path: str, value: Any) -> str:
        if not isinstance(value, str):
            self.fail(path, "a string", value)
        return value

    def nanoseconds(self, path: str, value: Any) -> int:
        return _Fields(self.source, value, path).get("nanoseconds", self.count)

    def since_epoch(self, path: str, value: Any) -> int:
        return _Fields(self.source, value, path).get("nanoseconds_since_epoch", self.count)

    def items(self, path: str, value: Any) -> list[Any]:
        if not isinstance(value, list):
            self.fail(path, "a list", value)
        return value

    def texts(self, path: str, value: Any) -> list[str]:
        return [self.text(f"{path}[{i}]", v) for i, v in enumerate(self.items(path, value))]

    def custom(self, path: str, value: Any) -> dict[str, str]:
        if value is None:       # what rosbag2 writes for an empty map
            return {}
        if not isinstance(value, dict):
            self.fail(path, "a map of strings", value)
        return {self.text(f"{path} key", k): self.text(f"{path}.{k}", v)
                for k, v in value.items()}

    def qos(self, path: str, value: Any, version: int) -> list[Qos]:
        if version >= 9:
            return qos_from_yaml(self.items(path, value), lambda msg: BagError(
                f"{self.source}: {path}: {msg}"))
        text = self.text(path, value)
        try:
            parsed = load_yaml(text) if text.strip() else []
        except yaml.YAMLError as exc:
            raise BagError(f"{self.source}: {path}: not YAML: {problem(exc)}") from None
        return self.qos(path, parsed if parsed is not None else [], 9)


def _topic(fields: _Fields, path: str, node: Any, version: int) -> TopicEntry:
    entry = _Fields(fields.source, node, path)
    meta = entry.get("topic_metadata", lambda p, v: _Fields(fields.source, v, p))
    qos = (meta.get("offered_qos_profiles", lambda p, v: meta.qos(p, v, version))
           if version >= 4 else [])
    return TopicEntry(
        name=meta.get("name", meta.text), type=meta.get("type", meta.text),
        serialization_format=meta.get("serialization_format", meta.text), offered_qos=qos,
        type_description_hash=(meta.get("type_description_hash", meta.text)
                               if version >= 7 else ""),
        message_count=entry.get("message_count", entry.count))


def _file(fields: _Fields, path: str, node: Any) -> FileEntry:
    entry = _Fields(fields.source, node, path)
    return FileEntry(path=entry.get("path", entry.text),
                     starting_time_ns=entry.get("starting_time", entry.since_epoch),
                     duration_ns=entry.get("duration", entry.nanoseconds),
                     message_count=entry.get("message_count", entry.count))


def parse_metadata(document: Any, source: Path) -> BagMetadata:
    """The metadata in ``document`` (parsed YAML), every field checked (module docstring)."""
    top = _Fields(source, document, "")
    info = top.get(ROOT_KEY, lambda p, v: _Fields(source, v, p))
    version = info.get("version", info.count)
    if not 1 <= version <= METADATA_VERSION:
        raise BagError(f"{source}: {ROOT_KEY}.version: {version} is not a rosbag2 metadata "
                       f"version this reads (1 to {METADATA_VERSION})")

    def topics(path: str, value: Any) -> list[TopicEntry]:
        return [_topic(info, f"{path}[{i}]", v, version)
                for i, v in enumerate(info.items(path, value))]

    def files(path: str, value: Any) -> list[FileEntry]:
        return [_file(info, f"{path}[{i}]", v) for i, v in enumerate(info.items(path, value))]

    return BagMetadata(
        version=version,
        storage_identifier=info.get("storage_identifier", info.text),
        relative_file_paths=info.get("relative_file_paths", info.texts),
        starting_time_ns=info.get("starting_time", info.since_epoch),
        duration_ns=info.get("duration", info.nanoseconds),
        message_count=info.get("message_count", info.count),
        topics=info.get("topics_with_message_count", topics),
        compression_format=info.get("compression_format", info.text) if version >= 3 else "",
        compression_mode=info.get("compression_mode", info.text) if version >= 3 else "",
        files=info.get("files", files) if version >= 5 else [],
        custom_data=info.get("custom_data", info.custom) if version >= 6 else {},
        ros_distro=info.get("ros_distro", info.text) if version >= 8 else "",
    )


def load_metadata(bag: Path) -> BagMetadata:
    """The bag directory's ``metadata.yaml``, checked; BagError naming it when it is missing,
    not a regular file of at most :data:`MAX_METADATA_BYTES`, not YAML (or YAML whose aliases
    expand past the loader's bounds), or has a field of the wrong type."""
    source = bag / METADATA_FILE
    directory(bag, what="bag directory", error=BagError)
    if not source.exists():
        raise BagError(f"{source}: missing (not a rosbag2 directory?)")
    raw = read_bytes(source, what="bag metadata file", max_bytes=MAX_METADATA_BYTES,
                     error=BagError)
    try:
        document = load_yaml(raw)
    except yaml.YAMLError as exc:
        raise BagError(f"{source}: not rosbag2 metadata: {problem(exc)}") from None
    except MemoryError:
        raise BagError(f"{source}: not rosbag2 metadata: too large to read") from None
    return parse_metadata(document, source)


def _time(ns: int) -> dict[str, int]:
    return {"nanoseconds_since_epoch": ns}


def dump_metadata(meta: BagMetadata, *, embedded: bool = False) -> str:
    """``metadata.yaml`` text of version 9, as ``ros2 bag record`` (Jazzy) writes it; with
    ``embedded`` the inner mapping alone, as rosbag2 writes it into the MCAP file's ``rosbag2``
    metadata record (``serialized_metadata``)."""
    info = {
        "version": METADATA_VERSION,
        "storage_identifier": meta.storage_identifier,
        "duration": {"nanoseconds": meta.duration_ns},
        "starting_time": _time(meta.starting_time_ns),
        "message_count": meta.message_count,
        "topics_with_message_count": [{
            "topic_metadata": {
                "name": t.name, "type": t.type, "serialization_format": t.serialization_format,
                "offered_qos_profiles": qos_to_yaml(t.offered_qos),
                "type_description_hash": t.type_description_hash},
            "message_count": t.message_count} for t in meta.topics],
        "compression_format": meta.compression_format,
        "compression_mode": meta.compression_mode,
        "relative_file_paths": list(meta.relative_file_paths),
        "files": [{"path": f.path, "starting_time": _time(f.starting_time_ns),
                   "duration": {"nanoseconds": f.duration_ns},
                   "message_count": f.message_count} for f in meta.files],
        "custom_data": dict(meta.custom_data) or None,
        "ros_distro": meta.ros_distro,
    }
    return yaml.safe_dump(info if embedded else {ROOT_KEY: info}, sort_keys=False, width=1000)


__all__ = ["METADATA_FILE", "METADATA_VERSION", "BagMetadata", "FileEntry", "TopicEntry",
           "dump_metadata", "load_metadata", "parse_metadata"]
