"""Helpers for the middleware tests: an isolated ROS domain per test and node subprocesses."""

from __future__ import annotations

import contextlib
import fcntl
import os
import random
import select
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from stillframe.locations import REPO_ROOT
from tests.support.waits import HANG_S

#: one lock file per ROS_DOMAIN_ID a test holds; ``flock`` so that a killed run frees its ids
DOMAIN_LOCKS = Path(tempfile.gettempdir()) / "stillframe-test-domains"
#: the ids tests draw from (Jazzy's default ports reach 232; 0 is everyone's default)
TEST_DOMAINS = range(1, 201)
#: how long [s] a released id rests before it is drawn again: longer than the DDS leases
#: (Cyclone 10 s, Fast DDS 20 s) after which a participant that a test left behind (a node
#: still stopping on a loaded machine, or killed) has left the graph, so the next test on the id
#: does not find it there ("another stillframe loop is running")
DOMAIN_REST_S = 60.0
#: how long [s] an aborted process has to write its threads' stacks before it is killed
ABORT_S = 20.0


@contextlib.contextmanager
def held_domain() -> Iterator[int]:
    """A ROS_DOMAIN_ID (1..200) no other test run on this machine holds, for as long as the
    ``with`` lasts. The id is drawn at random and held by an exclusive lock on its file, so two
    suites (or two workers of one suite) never share a domain; the file keeps the time the id
    was released, and an id released less than :data:`DOMAIN_REST_S` ago is not drawn. When
    every id is held or resting the draw waits for one."""
    DOMAIN_LOCKS.mkdir(exist_ok=True)
    ids = list(TEST_DOMAINS)
    random.SystemRandom().shuffle(ids)
    while True:
        for domain in ids:
            handle = (DOMAIN_LOCKS / f"{domain}.lock").open("a+")
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                handle.close()
                continue
            with handle:
                handle.seek(0)
                released = float(handle.read().strip() or 0.0)
                if time.time() - released < DOMAIN_REST_S:
                    continue
                try:
                    yield domain
                finally:
                    handle.truncate(0)
                    handle.write(f"{time.time()}\n")
            return
        time.sleep(0.1)


@contextlib.contextmanager
def isolated_domain(monkeypatch: pytest.MonkeyPatch) -> Iterator[int]:
    """A domain of :func:`held_domain`, discovery on this machine only and the dds backend, for
    as long as the ``with`` lasts."""
    with held_domain() as domain:
        monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
        monkeypatch.delenv("CYCLONEDDS_URI", raising=False)
        monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        monkeypatch.setenv("STILLFRAME_RMW", "dds")
        yield domain


def child_env() -> dict[str, str]:
    """The environment for a subprocess: this one (with ROS_DOMAIN_ID) plus the repo on the path,
    and Python's fault handler on, so that a child that hangs prints where each of its threads
    is when :func:`finish` aborts it."""
    return dict(os.environ, PYTHONPATH=str(REPO_ROOT), PYTHONUNBUFFERED="1",
                PYTHONFAULTHANDLER="1")


def start_python(code: str, *args: str, env: dict[str, str] | None = None) -> subprocess.Popen:
    """Run ``python -c code args...`` in the background (:func:`child_env` and ``env``), text pipes
    for stdout and stderr."""
    return subprocess.Popen(
        [sys.executable, "-c", code, *args], env={**child_env(), **(env or {})}, cwd=REPO_ROOT,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def run_stillframe(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    """``python -m stillframe args...`` to completion."""
    return subprocess.run(
        [sys.executable, "-m", "stillframe", *args], env=child_env(), cwd=REPO_ROOT,
        capture_output=True, text=True, timeout=timeout,
    )


def wait_for_line(proc: subprocess.Popen, text: str, timeout: float = HANG_S) -> str:
    """Read the process's stdout until a line containing ``text`` (fails on exit or timeout).

    The pipe is read a byte at a time, straight from its descriptor: ``select`` on a buffered
    stream misses the lines its buffer already holds (a process that logs two lines in one
    instant hands both to the first ``readline``, and the second then never wakes ``select``),
    and reading no further than the line leaves the rest in the pipe for later readers."""
    fd = proc.stdout.fileno()
    deadline = time.monotonic() + timeout
    lines: list[str] = []
    line = bytearray()
    while (remaining := deadline - time.monotonic()) > 0:
        if not select.select([fd], [], [], remaining)[0]:
            break
        byte = os.read(fd, 1)
        if not byte:
            break
        if byte != b"\n":
            line += byte
            continue
        lines.append(line.decode(errors="replace"))
        line.clear()
        if text in lines[-1]:
            return lines[-1] + "\n"
    proc.kill()
    said = "\n".join([*lines, line.decode(errors="replace")])
    raise AssertionError(f"no line with {text!r} in {timeout:g} s; it wrote: {said[-2000:]}")


def finish(proc: subprocess.Popen, timeout: float = HANG_S) -> tuple[str, str]:
    """Wait for the process; its remaining stdout and stderr. On timeout it is aborted (SIGABRT:
    the fault handler of :func:`child_env` writes every thread's Python stack, which works while
    the main thread is stuck in C code), killed if that does not end it, and the failure shows
    the end of its stderr."""
    try:
        return proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGABRT)
        try:
            _out, err = proc.communicate(timeout=ABORT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            _out, err = proc.communicate()
        raise AssertionError(f"process did not finish; stderr: {err[-6000:]}") from None


def niced(increment: int) -> int:
    """The niceness a child ends at when it lowers itself by ``increment``: children inherit this
    process's niceness (a suite may itself run niced, as CI runners often do) and the kernel
    caps it at 19."""
    return min(19, os.getpriority(os.PRIO_PROCESS, 0) + increment)


def scheduling(pid: int) -> set[tuple[int, int]]:
    """(policy, niceness) of each thread of ``pid`` (threads that end meanwhile left out)."""
    out = set()
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            tid = int(task)
            out.add((os.sched_getscheduler(tid), os.getpriority(os.PRIO_PROCESS, tid)))
        except (ProcessLookupError, FileNotFoundError):
            continue
    return out
