"""Opening the files a user names: only a regular file (or a directory where one is expected),
and only of a size its reader can take.

Every path the project reads or writes for a user (scenes, model files, parameter files, bags and
their ``metadata.yaml``, datasets, plots, ``--out``, ``--save-model``) goes through this module,
so that a FIFO, a character device (``/dev/zero``), a socket, a directory where a file is
expected or a file of gigabytes is one line naming it, never a read that blocks or never ends
(``tests/unit/base/test_files.py`` holds the library to it).

The kind is read with ``fstat`` on the descriptor that is then read (or written), not on the
name beforehand, so that nothing swapped in between gets through; the descriptor is opened with
``O_NONBLOCK``, so that a FIFO neither blocks the open (for reading: until a writer comes; for
writing: until a reader comes) nor is read. Errors are raised as the caller's kind:
:class:`~stillframe.errors.InputError` (exit code 2) by default, ``BagError`` (3) for a bag.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any, BinaryIO

from stillframe.errors import InputError, StillframeError

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))
_READ = os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC
_WRITE = os.O_WRONLY | os.O_CREAT | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC


def kind(mode: int) -> str:
    """What a file of ``st_mode`` is, in words (``a FIFO (named pipe)``; ``a file``)."""
    return next((name for test, name in _KINDS if test(mode)), "a file")


def size_text(size: int) -> str:
    """``2 GiB``, ``1 MiB``, ``512 KiB``, ``100 bytes``: a size as a message gives it."""
    for shift, unit in ((30, "GiB"), (20, "MiB"), (10, "KiB")):
        if size >= 1 << shift:
            return f"{size / (1 << shift):.3g} {unit}"
    return f"{size} bytes"


def _refuse(path: str | Path, info: os.stat_result, what: str, max_bytes: int | None,
            error: type[StillframeError], *, regular: bool = True) -> None:
    if regular and not stat.S_ISREG(info.st_mode):
        raise error(f"{path}: {kind(info.st_mode)}, not a {what}")
    if max_bytes is not None and info.st_size > max_bytes:
        raise error(f"{path}: {size_text(info.st_size)}, more than the {size_text(max_bytes)} "
                    f"a {what} may have")


def _descriptor(path: str | Path, flags: int, what: str, error: type[StillframeError],
                verb: str) -> int:
    try:
        info = os.stat(path)
    except FileNotFoundError:
        info = None         # to be made (writing), else the open says so
    except OSError as exc:
        raise error(f"{path}: cannot {verb} the {what} ({exc.strerror})") from None
    if info is not None and not stat.S_ISREG(info.st_mode):
        raise error(f"{path}: {kind(info.st_mode)}, not a {what}")
    try:
        return os.open(path, flags, 0o666)
    except OSError as exc:
        raise error(f"{path}: cannot {verb} the {what} ({exc.strerror})") from None


def _stream(fd: int, path: str | Path, mode: str) -> BinaryIO:
    """The descriptor, blocking again, as a file object named ``path`` (as ``open`` names it)."""
    os.set_blocking(fd, True)
    stream = os.fdopen(fd, mode)
    stream.raw.name = os.fspath(path)      # type: ignore[attr-defined]
    return stream


def open_input(path: str | Path, *, what: str, max_bytes: int | None = None,
               error: type[StillframeError] = InputError) -> BinaryIO:
    """``path`` opened for reading in binary, if it is a regular file of at most ``max_bytes``
    (None: any size, for a reader that seeks, as an MCAP reader does); else ``error`` naming
    the path and what it is (``what``: ``scene file``, ``model file``)."""
    fd = _descriptor(path, _READ, what, error, "read")
    try:
        _refuse(path, os.fstat(fd), what, max_bytes, error)
        return _stream(fd, path, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path: str | Path, *, what: str, max_bytes: int,
               error: type[StillframeError] = InputError) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` (:func:`open_input`); a file that
    grows past the bound while it is read is refused too."""
    with open_input(path, what=what, max_bytes=max_bytes, error=error) as stream:
        data = stream.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise error(f"{path}: more than the {size_text(max_bytes)} a {what} may have")
    return data


def open_output(path: str | Path, *, what: str,
                error: type[StillframeError] = InputError) -> BinaryIO:
    """``path`` opened for writing in binary (made, or emptied if it is a regular file); a FIFO,
    a device, a socket or a directory there is ``error`` naming it, and is neither opened for
    long nor written."""
    fd = _descriptor(path, _WRITE, what, error, "write")
    try:
        _refuse(path, os.fstat(fd), what, None, error)
        os.ftruncate(fd, 0)
        return _stream(fd, path, "wb")
    except BaseException:
        os.close(fd)
        raise


def write_text(path: str | Path, text: str, *, what: str) -> None:
    """``text`` (UTF-8) written to ``path`` through :func:`open_output`."""
    with open_output(path, what=what) as stream:
        stream.write(text.encode("utf-8"))


def directory(path: str | Path, *, what: str,
              error: type[StillframeError] = InputError) -> Path:
    """``path`` if it is a directory (``what``: ``bag directory``); else ``error`` naming it."""
    try:
        info = os.stat(path)
    except OSError as exc:
        raise error(f"{path}: not a {what} ({exc.strerror})") from None
    if not stat.S_ISDIR(info.st_mode):
        raise error(f"{path}: {kind(info.st_mode)}, not a {what}")
    return Path(path)


def check_output(option: str, path: str | Path | None, *, folder: bool = False) -> None:
    """Before any work: InputError when ``path`` (a file to write, or with ``folder`` a
    directory to write into) cannot be made: something of another kind there already (a FIFO,
    a device, a directory where a file goes, a file where a directory goes), an ancestor that
    is a file, or a directory that cannot be written (read-only)."""
    if path is None:
        return
    target = Path(path)
    try:
        info = os.stat(target)
    except OSError:
        info = None
    if info is not None and not (stat.S_ISDIR if folder else stat.S_ISREG)(info.st_mode):
        wanted = "a directory" if folder else "a file to write"
        raise InputError(f"{option} {target}: {kind(info.st_mode)}, not {wanted}")
    existing = next(p for p in (target, *target.parents) if p.exists() or p == Path(p.anchor))
    if existing != target and not existing.is_dir():
        raise InputError(f"{option} {target}: {existing} is a file, not a directory")
    parent = existing if existing.is_dir() else existing.parent
    if not os.access(parent, os.W_OK):
        raise InputError(f"{option} {target}: {parent} is not writable")


def save_figure(figure: Any, path: str | Path, *, dpi: int) -> None:
    """A matplotlib figure written to ``path`` through :func:`open_output`, in the format its
    suffix names (``.png``)."""
    with open_output(path, what="plot") as stream:
        figure.savefig(stream, format=Path(path).suffix.lstrip(".").lower() or None, dpi=dpi)
