"""Open only what can be read (``stillframe/files.py``): every kind of file that is not a regular
file, every size past a bound, for reading and for writing, refused in one line naming it and
without blocking; and no module of the library opens a user's path past it (a scan of the
source)."""

from __future__ import annotations

import ast
import os
import socket
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest

from stillframe import files
from stillframe.errors import BagError, InputError
from stillframe.locations import REPO_ROOT

#: the bound of the tests below; the sparse file is far past it, as a 2 GB one is past a scene's
BOUND = 1 << 20


def special_files(root: Path) -> dict[str, Path]:
    """A path of every kind that is not a regular file (kind as :func:`files.kind` names it):
    a FIFO without a writer (an open for reading blocks on it), character devices (one
    endless), a listening Unix socket, a directory, a symbolic link to a FIFO."""
    fifo = root / "fifo"
    os.mkfifo(fifo)
    sock = root / "socket"
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(sock))
    server.listen()
    (root / "link").symlink_to(fifo)
    (root / "dir").mkdir()
    return {"a FIFO (named pipe)": fifo, "a character device": Path("/dev/zero"),
            "a character device ": Path("/dev/urandom"), "a socket": sock,
            "a directory": root / "dir", "a FIFO (named pipe) ": root / "link"}


@pytest.fixture
def specials(tmp_path: Path) -> Iterator[dict[str, Path]]:
    yield special_files(tmp_path)


def test_every_special_kind_is_refused_for_reading_by_name(specials: dict[str, Path]) -> None:
    for kind, path in specials.items():
        for error in (InputError, BagError):
            with pytest.raises(error) as caught:
                files.read_bytes(path, what="scene file", max_bytes=BOUND, error=error)
            assert str(caught.value) == f"{path}: {kind.strip()}, not a scene file"
            with pytest.raises(error) as caught:
                files.open_input(path, what="scene file", error=error)
            assert str(caught.value) == f"{path}: {kind.strip()}, not a scene file"


def test_every_special_kind_is_refused_for_writing_and_left_as_it_was(
        specials: dict[str, Path]) -> None:
    """Nothing is written into a FIFO (even one with a reader), a device or a socket."""
    reader = os.open(specials["a FIFO (named pipe)"], os.O_RDONLY | os.O_NONBLOCK)
    try:
        for kind, path in specials.items():
            with pytest.raises(InputError) as caught:
                files.open_output(path, what="plot")
            assert str(caught.value) == f"{path}: {kind.strip()}, not a plot"
            with pytest.raises(InputError) as caught:
                files.check_output("--out", path)
            assert str(caught.value) == f"--out {path}: {kind.strip()}, not a file to write"
        assert os.read(reader, 10) == b""                # nothing reached the FIFO's reader
    finally:
        os.close(reader)


def test_a_huge_sparse_file_is_refused_before_it_is_read(tmp_path: Path) -> None:
    huge = tmp_path / "huge.yaml"
    with huge.open("wb") as stream:
        stream.truncate(2 << 30)                         # 2 GiB, no blocks on disk
    with pytest.raises(InputError) as caught:
        files.read_bytes(huge, what="scene file", max_bytes=BOUND)
    assert str(caught.value) == f"{huge}: 2 GiB, more than the 1 MiB a scene file may have"
    with pytest.raises(InputError, match="2 GiB"):
        files.open_input(huge, what="model file", max_bytes=BOUND)
    with files.open_input(huge, what="storage file") as stream:     # no bound: a reader seeks
        stream.seek(-3, os.SEEK_END)
        assert stream.read() == b"\0\0\0"


def test_a_file_at_the_bound_reads_and_one_byte_more_does_not(tmp_path: Path) -> None:
    path = tmp_path / "scene.yaml"
    path.write_bytes(b"x" * BOUND)
    assert files.read_bytes(path, what="scene file", max_bytes=BOUND) == b"x" * BOUND
    path.write_bytes(b"x" * (BOUND + 1))
    with pytest.raises(InputError, match="more than the 1 MiB"):
        files.read_bytes(path, what="scene file", max_bytes=BOUND)


def test_missing_and_unreadable_files_name_the_reason(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"missing\.yaml: cannot read the scene file \(No such"):
        files.read_bytes(tmp_path / "missing.yaml", what="scene file", max_bytes=BOUND)
    with pytest.raises(BagError, match=r"nodir: not a bag directory \(No such file"):
        files.directory(tmp_path / "nodir", what="bag directory", error=BagError)
    with pytest.raises(BagError, match="a character device, not a bag directory"):
        files.directory("/dev/null", what="bag directory", error=BagError)


def test_output_replaces_a_regular_file_and_makes_a_new_one(tmp_path: Path) -> None:
    old = tmp_path / "old.json"
    old.write_text("a much longer earlier content")
    files.write_text(old, "{}", what="result file")
    files.write_text(tmp_path / "new.json", "[]", what="result file")
    assert old.read_text() == "{}" and (tmp_path / "new.json").read_text() == "[]"
    assert stat.S_IMODE(old.stat().st_mode) & 0o600 == 0o600


def test_output_folders(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    files.check_output("--out", tmp_path, folder=True)              # an existing directory
    files.check_output("--out", tmp_path / "new" / "deeper", folder=True)
    with pytest.raises(InputError, match="a file, not a directory"):
        files.check_output("--out", blocker, folder=True)
    with pytest.raises(InputError, match=f"{blocker} is a file, not a directory"):
        files.check_output("--out", blocker / "x.npz")
    with pytest.raises(InputError, match="a directory, not a file to write"):
        files.check_output("--save-model", tmp_path)


# -- no module opens a user's path past stillframe/files.py -----------------------------------

#: calls that open, read or write a path: a method of that name on anything (a Path, a figure),
#: or these functions
METHODS = {"open", "read_text", "read_bytes", "write_text", "write_bytes", "savefig"}
FUNCTIONS = {"open", "np.load", "numpy.load", "pickle.load", "scipy.io.loadmat",
             "scipy.io.savemat", "np.savez", "np.savez_compressed", "np.savetxt", "np.loadtxt",
             "np.genfromtxt", "np.fromfile", "make_reader", "AnyReader", "Reader", "Writer"}
#: calls of those names that open no path: descriptors, archive members, rosbags' own
NOT_FILES = {"os.open", "archive.zip.open", "self._writer.open", "reader.open"}
#: (module, function) that open paths directly, and why that is safe: the process's own files,
#: written in this run or by this package, /proc, generated documentation
OWN = {
    ("stillframe/app/cli.py", "synopsis"): "the source of a command module of this package",
    ("stillframe/app/launcher.py", "Child.waited_s"): "/proc/PID/schedstat",
    ("stillframe/app/launcher.py", "catches_sigint"): "/proc/PID/status",
    ("stillframe/app/launcher.py", "Launcher._partial"): "sim_node's result of this run",
    ("stillframe/app/launcher.py", "Launcher._result"): "sim_node's result of this run",
    ("stillframe/app/tracking.py", "read_tracked"): "the tracker's record of this launch",
    ("stillframe/app/graph_daemon.py", "start"): "the daemon's own lock and log files",
    ("stillframe/app/bench/fault_runs.py", "lockstep_row"): "the history of this benchmark's run",
    ("stillframe/app/bench/fault_runs.py", "realtime_row"): "the history of this benchmark's run",
    ("stillframe/app/experiment_report.py", "plot_comparison"): "this experiment's histories",
    ("stillframe/app/commands/demo.py", "controlled_floors"): "the history the demo's launch "
                                                              "wrote",
    ("stillframe/bags/storage.py", "open_bag"): "after _check_dir checked every file",
    ("stillframe/bags/full_disk.py", "DiskLedger.__init__"): "the writer's reserve file",
    ("stillframe/contract/messages.py", "register_services"): "the package's .srv files",
    ("stillframe/fidelity/auto_model.py", "load_table"): "the package's fidelity table",
    ("stillframe/monitor/dashboard.py", "_asset"): "the package's dashboard page",
    ("stillframe/studies/cluster.py", "local_processes"): "the scheduler's file it made",
    ("stillframe/app/bench/recorder_load.py", "cpu_time_s"): "/proc/PID/stat",
    ("stillframe/app/bench/recorder_load.py", "write_limit"): "a temporary file of its own",
    ("stillframe/app/bench/settle.py", "cpu_times"): "/proc/stat",
    ("stillframe/app/bench/settle.py", "live_children"): "/proc/PID/stat",
    ("stillframe/app/bench/rss.py", "rss_bytes"): "/proc/PID/status",
    ("stillframe/app/bench/stall_probe.py", "stall_probe"): "the probe's own log",
    ("stillframe/node_runtime/realtime.py", "_loop_threads"): "/proc/self/task",
    ("stillframe/config/environment.py", "<module>"): "regenerates docs/middleware.md",
    ("stillframe/node_runtime/declarations.py", "<module>"): "regenerates docs/nodes.md",
    ("stillframe/node_runtime/qos_table.py", "<module>"): "regenerates docs/nodes.md",
    ("identification/node.py", "ModalTrackerNode.write"): "appends to the launch's record",
    ("stillframe/app/adaptation_plot.py", "plot_timeline"): "the histories of adapt's own runs",
    ("stillframe/app/launcher.py", "Launcher._name_writers"): "sim_node's result of this run",
    ("stillframe/bags/full_disk.py", "mcap_writer"): "the writer's own storage file",
    ("stillframe/bags/full_disk.py", "_ReplayStream.__init__"): "the writer's own storage file",
    ("stillframe/bags/full_disk.py", "close_after_failure"): "the writer's own storage file",
    ("stillframe/bags/full_disk.py", "_complete_chunks"): "the writer's own storage file",
    ("stillframe/bags/storage.py", "BagWriter._write_metadata"): "the writer's own metadata",
    ("stillframe/app/bench/phases.py", "NodeRing.load"): "the phase log a node of this run wrote",
    ("stillframe/node_runtime/phase_timing.py", "PhaseLog.write"): "the launch's own phase-log "
                                                                   "directory",
    ("stillframe/node_runtime/phase_timing.py", "_read"): "/proc/self/sched, /proc/sys/kernel",
    ("stillframe/node_runtime/realtime.py", "capable"): "/proc/self/status",
    ("stillframe/node_runtime/realtime.py", "_mapped_bytes"): "/proc/self/status",
}
SOURCES = ("stillframe", "sim_node", "estimator_node", "controller_node", "container_node",
           "identification")


def _name(node: ast.expr) -> str:
    """``np.load`` of the call ``np.load(...)``'s function; '' for what has no dotted name."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        inner = _name(node.value)
        return f"{inner}.{node.attr}" if inner else f"?.{node.attr}"
    return ""


def direct_opens(path: Path) -> Iterator[tuple[str, int, str]]:
    """(function, line, call) of each call in ``path`` that opens a path by its own means. A
    call on a stream from :mod:`stillframe.files` (``with open_output(...) as stream``, or a
    parameter typed ``BinaryIO``) is not one."""

    def visit(node: ast.AST, where: list[str], streams: set[str]) -> Iterator[tuple]:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            if not isinstance(node, ast.ClassDef):
                streams = streams | {a.arg for a in node.args.args
                                     if a.annotation is not None
                                     and "IO" in ast.unparse(a.annotation)}
            where = [*where, node.name]
        if isinstance(node, ast.With):
            streams = streams | {item.optional_vars.id for item in node.items
                                 if isinstance(item.optional_vars, ast.Name)
                                 and "open_" in ast.unparse(item.context_expr)}
        if isinstance(node, ast.Call):
            name = _name(node.func)
            first = node.args[0] if node.args else None
            on_stream = isinstance(first, ast.Name) and first.id in streams
            method = isinstance(node.func, ast.Attribute) and node.func.attr in METHODS
            if (method or name in FUNCTIONS) and name not in NOT_FILES and not on_stream \
                    and name.split(".")[0] not in through_files:
                yield ".".join(where) or "<module>", node.lineno, name
        for child in ast.iter_child_nodes(node):
            yield from visit(child, where, streams)

    tree = ast.parse(path.read_text())
    through_files = {"files", *(alias.asname or alias.name for node in ast.walk(tree)
                                if isinstance(node, ast.ImportFrom)
                                and node.module == "stillframe.files" for alias in node.names)}
    yield from visit(tree, [], set())


def test_no_module_opens_a_users_path_past_files() -> None:
    """Every open, read or write of a path in the library and the node packages goes through
    :mod:`stillframe.files`, or is one of :data:`OWN` (the process's own files), each listed
    with its reason; a new direct one fails here until it does either."""
    found, used = {}, set()
    for package in SOURCES:
        for path in sorted((REPO_ROOT / package).rglob("*.py")):
            module = str(path.relative_to(REPO_ROOT))
            if module == "stillframe/files.py":
                continue
            for function, line, call in direct_opens(path):
                if (module, function) in OWN:
                    used.add((module, function))
                else:
                    found[f"{module}:{line}"] = f"{call}() in {function}"
    assert not found, f"open through stillframe.files (or list as the process's own): {found}"
    assert used == set(OWN), f"listed but opening nothing: {set(OWN) - used}"


def test_the_scan_sees_a_direct_open(tmp_path: Path) -> None:
    """The scan can fail: each way of opening a path is found, a stream from files is not."""
    source = tmp_path / "m.py"
    source.write_text(
        "import numpy as np, yaml\n"
        "from stillframe.files import read_bytes\n"
        "def f(path, stream: BinaryIO):\n"
        "    yaml.safe_load(open(path))\n"
        "    path.read_text()\n"
        "    np.load(path)\n"
        "    with files.open_output(path, what='x') as out:\n"
        "        np.savez(out, a=1)\n"
        "    np.savez(stream, a=1)\n"
        "    fig.savefig(path)\n"
        "    read_bytes(path, what='x', max_bytes=1)\n")
    assert list(direct_opens(source)) == [("f", 4, "open"), ("f", 5, "path.read_text"),
                                          ("f", 6, "np.load"), ("f", 10, "fig.savefig")]
