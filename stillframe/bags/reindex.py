"""Recover a bag whose recorder was killed (SIGKILL, power loss): ``stillframe bag reindex DIR``.

A killed recorder leaves an MCAP file without its summary and footer, and no ``metadata.yaml``
(:mod:`stillframe.bags.storage`: both are written on close). The ``mcap`` package's
:class:`~mcap.stream_reader.StreamReader` reads such a file front to back and yields the records
of every chunk it can read completely (with CRC checks), then stops at the truncated tail; the
package has no recovery routine of its own (the Go ``mcap recover`` CLI is not on PyPI). The
recovered schemas, channels and messages are written again with
:class:`stillframe.bags.storage.BagWriter`
into a complete bag in DIR (the damaged file kept beside it as ``*.damaged``), which
``ros2 bag``, rosbags and ``mcap`` read. Like ``ros2 bag reindex``, what was recorded up to the
last complete chunk survives; the messages of the chunk being filled when the recorder died are
lost.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys.store import Typestore

from stillframe.bags.full_disk import RESERVE_NAME
from stillframe.bags.storage import BagWriter
from stillframe.errors import BagError


@dataclass(frozen=True)
class Recovered:
    """What reindexing kept: messages per topic, and whether the file was cut short."""

    path: Path
    counts: dict[str, int]
    truncated: bool

    @property
    def total(self) -> int:
        return sum(self.counts.values())


def _mcap_file(bag: Path) -> Path:
    if not bag.is_dir():
        raise BagError(f"{bag}: not a bag directory (no such directory)")
    files = sorted(bag.glob("*.mcap"))
    if len(files) != 1:
        raise BagError(f"{bag}: expected one .mcap file to reindex, found {len(files)}")
    return files[0]


def read_complete_chunks(path: Path) -> tuple[list[Schema], dict[int, Channel],
                                              list[Message], bool]:
    """Schemas, channels and messages of every complete chunk, and whether the file was cut."""
    schemas: list[Schema] = []
    channels: dict[int, Channel] = {}
    found: list[Message] = []
    truncated = False
    with path.open("rb") as stream:
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas.append(record)
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    found.append(record)
        except (McapError, ValueError, EOFError):
            truncated = True
    return schemas, channels, found, truncated


def reindex(bag: str | Path, typestore: Typestore) -> Recovered:
    """Rewrite the bag at ``bag`` from its complete chunks (module docstring)."""
    bag = Path(bag)
    source = _mcap_file(bag)
    (bag / RESERVE_NAME).unlink(missing_ok=True)    # a killed recorder's reserve: room to work
    schemas, channels, found, truncated = read_complete_chunks(source)
    names = {s.id: s.name for s in schemas}
    with tempfile.TemporaryDirectory(dir=bag.parent) as tmp:
        fresh = Path(tmp) / bag.name
        with BagWriter(fresh, typestore) as writer:
            topics: dict[int, str] = {}
            for channel in channels.values():
                qos = parse_qos(channel.metadata.get("offered_qos_profiles", ""))
                writer.add_topic(channel.topic, names[channel.schema_id], qos)
                topics[channel.id] = channel.topic
            for message in sorted(found, key=lambda m: m.log_time):
                writer.write(topics[message.channel_id], message.log_time, message.data)
            counts = {topic: writer.count(topic) for topic in sorted(topics.values())}
        source.rename(source.with_name(source.name + ".damaged"))
        (bag / "metadata.yaml").unlink(missing_ok=True)
        for item in fresh.iterdir():
            shutil.move(str(item), bag / item.name)
    return Recovered(bag, counts, truncated)
