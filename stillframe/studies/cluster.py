"""A Dask cluster of separate processes on this machine: ``dask scheduler`` and ``dask worker``
started as subprocesses on 127.0.0.1 (random ports), the stand-in for a cluster of machines in
the scaling benchmark and the tests."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from stillframe.errors import InputError
from stillframe.locations import PACKAGE_DIR

START_TIMEOUT_S = 60.0


def dask_executable() -> str:
    """The ``dask`` command beside this Python (the venv's), else the one on PATH."""
    beside = Path(sys.executable).parent / "dask"
    found = str(beside) if beside.exists() else shutil.which("dask")
    if not found:
        raise InputError("dask: the dask command is missing (pip install 'dask[distributed]')")
    return found


def _wait_for(client_address: str, workers: int, procs: list[subprocess.Popen]) -> None:
    from distributed import Client

    with Client(client_address, timeout=START_TIMEOUT_S) as client:
        deadline = time.monotonic() + START_TIMEOUT_S
        while len(client.scheduler_info()["workers"]) < workers:
            dead = [p.args for p in procs if p.poll() is not None]
            if dead or time.monotonic() > deadline:
                raise InputError(f"dask cluster: {workers} workers did not start "
                                 f"({'exited: ' + str(dead[0]) if dead else 'timeout'})")
            time.sleep(0.1)


@contextmanager
def local_processes(workers: int) -> Iterator[str]:
    """Start a scheduler and ``workers`` single-threaded workers; yield the scheduler address;
    stop them (the processes started here, by id) on exit."""
    dask = dask_executable()
    procs: list[subprocess.Popen] = []
    with tempfile.TemporaryDirectory(prefix="stillframe-dask-") as tmp:
        info = Path(tmp) / "scheduler.json"
        # the workers import the same stillframe as this process (a consistent environment)
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            p for p in (str(PACKAGE_DIR.parent), os.environ.get("PYTHONPATH", "")) if p))
        quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env}
        try:
            procs.append(subprocess.Popen(
                [dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                 "--dashboard-address", "127.0.0.1:0",
                 "--scheduler-file", str(info)], **quiet))
            deadline = time.monotonic() + START_TIMEOUT_S
            while not info.exists() or not info.read_text().strip():
                if procs[0].poll() is not None or time.monotonic() > deadline:
                    raise InputError("dask scheduler: did not start")
                time.sleep(0.05)
            address = json.loads(info.read_text())["address"]
            for _ in range(workers):
                procs.append(subprocess.Popen(
                    [dask, "worker", address, "--host", "127.0.0.1", "--nthreads", "1",
                     "--no-dashboard", "--local-directory", tmp], **quiet))
            _wait_for(address, workers, procs)
            yield address
        finally:
            for p in reversed(procs):
                p.terminate()
            for p in reversed(procs):
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
