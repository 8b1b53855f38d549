"""Helpers for the loop-node tests: parameter files, node processes, a full three-node run."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
import yaml

from stillframe.contract import topics
from stillframe.locations import REPO_ROOT
from tests.support.middleware import child_env, finish, start_python
from tests.support.waits import HANG_S

SCENES = REPO_ROOT / "scenes"
SHORT_LQG = ["duration=6", "controller.start=3", "evaluation.window=2"]


def assert_same_histories(histories: Any, reference: Any) -> None:
    """Every history the simulator wrote (``histories``: its ``.npz``, as sim_node's
    ``write_result`` names them) equals the one-process loop's of that name (``reference``, a
    :class:`stillframe.loop.evaluation.LoopHistory`) to the last bit; a difference is named by
    its history, its first row and that row's time, which says where timing entered the run and
    which node it reached first (the command before the truth: the controller's side)."""
    keys = list(histories)
    assert {"truth", "command", "fine_floors"} <= set(keys), keys
    first = []
    for key in keys:
        got, want = np.asarray(histories[key]), np.asarray(getattr(reference, key))
        assert got.shape == want.shape, (key, got.shape, want.shape)
        rows = np.flatnonzero(np.any((got != want).reshape(len(got), -1), axis=1))
        if rows.size:
            times = reference.fine_t if key.startswith("fine_") else reference.t
            row = int(rows[0])
            first.append(f"{key}: {rows.size} rows differ, the first at row {row} "
                         f"(t = {times[row]:.6f} s): {got[row].tolist()} != {want[row].tolist()}")
    assert not first, "; ".join(first)


def params_file(tmp_path: Path, scene: str, overrides: list[str], **params: Any) -> Path:
    """A ROS 2 parameter file giving every node (``/**``) the scene and ``params``."""
    path = tmp_path / "params.yaml"
    body = {"scene": str(SCENES / f"{scene}.yaml"), **params}
    if overrides:   # a ROS parameter cannot be an empty list
        body["overrides"] = overrides
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": body}}))
    return path


def start_node(package: str, params: Path, *args: str) -> subprocess.Popen:
    """``python -m PACKAGE.node --ros-args --params-file PARAMS ARGS...`` in the background."""
    return subprocess.Popen(
        [sys.executable, "-m", f"{package}.node", "--ros-args", "--params-file", str(params),
         *args],
        env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True,
    )


def wait_for_log(proc: subprocess.Popen, text: str, timeout: float = HANG_S) -> str:
    """Read the node's log (stderr) until a line containing ``text``. The lines are read in a
    thread, not by ``select`` on the pipe: a burst of lines sits in the text stream's buffer
    after the first ``readline``, where ``select`` on the empty pipe cannot see it."""
    found: list[str] = []

    def scan() -> None:
        for line in proc.stderr:
            if text in line:
                found.append(line)
                return

    reader = threading.Thread(target=scan, daemon=True)
    reader.start()
    reader.join(timeout)
    if found:
        return found[0]
    proc.kill()
    reader.join(5)
    raise AssertionError(f"no log line with {text!r}")


def stop(proc: subprocess.Popen, sig: int = signal.SIGINT) -> tuple[int, str]:
    """Send ``sig``, wait; the exit code and stderr."""
    if proc.poll() is None:
        proc.send_signal(sig)
    _out, err = finish(proc, timeout=120)
    return proc.returncode, err


def run_loop(tmp_path: Path, scene: str, overrides: list[str], *, log: list[str] | None = None,
             **params: Any) -> tuple[dict, dict[str, np.ndarray]]:
    """The three nodes as processes; the sim's result JSON and histories (and its log lines
    appended to ``log``). Fails unless every node exits 0 (the estimator and controller on
    SIGINT after the sim finished)."""
    result, histories, lines = run_loop_until(tmp_path, scene, overrides, None, **params)
    if log is not None:
        log.extend(lines)
    return result, histories


def run_loop_until(tmp_path: Path, scene: str, overrides: list[str],
                   until: Callable[[list[str]], bool] | None, *, timeout: float = 300,
                   **params: Any) -> tuple[dict, dict[str, np.ndarray], list[str]]:
    """:func:`run_loop`, with the simulator stopped by SIGINT as soon as ``until(its log lines
    so far)`` holds (None: the scene runs to its end); also the simulator's log lines. Fails if
    the simulator ends before ``until`` holds, or ``timeout`` seconds pass. Stopped, the
    simulator writes the samples run so far (``"complete": false``)."""
    result = tmp_path / "result.json"
    pfile = params_file(tmp_path, scene, overrides, result_file=str(result), **params)
    peers = [start_node(name, pfile) for name in ("estimator_node", "controller_node")]
    sim = start_node("sim_node", pfile)
    log, _out = read_lines(sim.stderr), read_lines(sim.stdout)   # both drained
    try:
        if until is not None:
            deadline = time.monotonic() + timeout
            while not until(log.lines):
                assert sim.poll() is None, f"the simulator ended first: {log.text()[-3000:]}"
                assert time.monotonic() < deadline, f"not seen in {timeout:g} s: " \
                    f"{log.text()[-3000:]}"
                time.sleep(0.05)
            sim.send_signal(signal.SIGINT)
        sim.wait(timeout=300)
    finally:
        if sim.poll() is None:
            sim.kill()
        codes = [stop(p) for p in peers]
    log.reader.join(10)
    assert sim.returncode == 0, log.text()[-2000:]
    for code, err in codes:
        assert code == 0, err[-2000:]
    with np.load(result.with_suffix(".npz")) as data:
        histories = dict(data)
    return json.loads(result.read_text()), histories, log.lines


@dataclass
class Lines:
    """The lines of a process's stream, read by a thread as they come."""

    reader: threading.Thread
    lines: list[str] = field(default_factory=list)

    def text(self) -> str:
        return "".join(self.lines)


def read_lines(stream: IO[str]) -> Lines:
    """Read ``stream`` line by line in a daemon thread into :attr:`Lines.lines`."""
    lines: list[str] = []

    def read() -> None:
        for line in stream:
            lines.append(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    return Lines(reader, lines)


def run_loop_beside(tmp_path: Path, writer_code: str, scene: str, overrides: list[str], *,
                    log: list[str] | None = None,
                    **params: Any) -> tuple[dict, dict[str, np.ndarray], int]:
    """:func:`run_loop` while another process runs ``writer_code`` (a Python script that prints
    ``ready``, writes until SIGTERM and then prints ``sent N``); also returns N."""
    writer = start_python(writer_code)
    assert writer.stdout.readline().strip() == "ready"
    try:
        result, hist = run_loop(tmp_path, scene, overrides, log=log, **params)
    finally:
        writer.send_signal(signal.SIGTERM)
        out, err = finish(writer, timeout=120)
    assert writer.returncode == 0, err[-2000:]
    return result, hist, int(out.split()[-1])


class Statuses:
    """The newest ``/diagnostics`` status of each node (level, message, values)."""

    def __init__(self, node: object) -> None:
        self.latest: dict[str, tuple[int, str, dict[str, str]]] = {}
        node.create_subscription(topics.DIAGNOSTICS.type_name, "/diagnostics", self.on_status,
                                 "default")

    def on_status(self, msg: object) -> None:
        for s in msg.status:
            self.latest[s.name] = (s.level, s.message, {kv.key: kv.value for kv in s.values})

    def stale(self, name: str) -> bool:
        level, message, _ = self.latest.get(f"/frame/{name}", (0, "", {}))
        return level == 2 and "stale input" in message
