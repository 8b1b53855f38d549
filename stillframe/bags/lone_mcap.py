"""A lone ``.mcap`` file read like a bag directory (``ros2 bag info FILE.mcap`` does the same).

rosbags' readers need the directory's ``metadata.yaml``; a lone MCAP file (copied out of a bag,
or written by another tool) has none. :func:`open_lone_mcap` reads it with the ``mcap`` package
and deserialises with rosbags' typestore, offering the subset of ``AnyReader`` that the channel
reader uses: ``connections`` (topic and type), ``messages(connections=…)`` yielding
``(connection, log_time, raw)`` and ``deserialize(raw, msgtype)``. Types the default typestore
lacks are registered from the file's ``ros2msg`` schemas.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.exceptions import McapError
from mcap.reader import make_reader
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import Typestore

from stillframe.errors import BagError
from stillframe.files import open_input


@dataclass(frozen=True)
class LoneConnection:
    """A topic of the file, as rosbags' ``Connection`` names it."""

    id: int
    topic: str
    msgtype: str


class LoneMcapReader:
    """The part of ``AnyReader``'s interface that :mod:`stillframe.bags.channels` uses."""

    def __init__(self, stream: BinaryIO, path: Path, typestore: Typestore) -> None:
        self._path = path
        self._reader = make_reader(stream)
        self._typestore = typestore
        try:
            summary = self._reader.get_summary()
        except (McapError, ValueError, EOFError) as exc:
            raise BagError(f"{path}: unreadable MCAP file: {exc}") from None
        if summary is None:
            raise BagError(f"{path}: MCAP file without a summary (run `stillframe bag reindex` "
                           "on a directory holding it)")
        schemas = summary.schemas
        self.connections = [LoneConnection(c.id, c.topic, schemas[c.schema_id].name)
                            for c in summary.channels.values() if c.schema_id in schemas]
        missing = {}
        for schema in schemas.values():
            if schema.name not in typestore.fielddefs and schema.encoding == "ros2msg":
                missing |= get_types_from_msg(schema.data.decode(), schema.name)
        if missing:
            typestore.register(missing)

    def messages(self, connections: Sequence[LoneConnection] = ()
                 ) -> Iterator[tuple[LoneConnection, int, bytes]]:
        by_topic = {c.topic: c for c in connections or self.connections}
        try:
            for _, channel, message in self._reader.iter_messages(topics=list(by_topic)):
                yield by_topic[channel.topic], message.log_time, message.data
        except (McapError, ValueError, EOFError) as exc:
            raise BagError(f"{self._path}: corrupt message data: {exc}") from None

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        return self._typestore.deserialize_cdr(raw, msgtype)


def is_lone_mcap(path: str | Path) -> bool:
    """Whether ``path`` ends in ``.mcap`` and is not a bag directory (what else it is, the
    opening says)."""
    return Path(path).suffix == ".mcap" and not Path(path).is_dir()


@contextmanager
def open_lone_mcap(path: str | Path, typestore: Typestore) -> Iterator[LoneMcapReader]:
    """An open :class:`LoneMcapReader` of ``path``."""
    path = Path(path)
    with open_input(path, what="storage file (MCAP)", error=BagError) as stream:
        yield LoneMcapReader(stream, path, typestore)
