"""A lone ``.mcap`` file read like a bag directory (``ros2 bag info FILE.mcap`` does the same).

A lone MCAP file (copied out of a bag, or written by another tool) has no ``metadata.yaml``;
:func:`open_lone_mcap` checks and reads it as :func:`stillframe.bags.storage.open_bag` reads a
bag's storage file (:mod:`stillframe.bags.checked_mcap`), types the typestore lacks learnt from
the file's ``ros2msg`` schemas.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from rosbags.typesys.store import Typestore

from stillframe.bags.checked_mcap import check_mcap
from stillframe.bags.storage import BagReader


def is_lone_mcap(path: str | Path) -> bool:
    """Whether ``path`` ends in ``.mcap`` and is not a bag directory (what else it is, the
    opening says)."""
    return Path(path).suffix == ".mcap" and not Path(path).is_dir()


@contextmanager
def open_lone_mcap(path: str | Path, typestore: Typestore) -> Iterator[BagReader]:
    """An open, checked :class:`~stillframe.bags.storage.BagReader` of the file at ``path``."""
    yield BagReader([check_mcap(path)], typestore)
