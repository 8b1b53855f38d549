"""Run many independent tasks on Dask distributed (docs/montecarlo.md).

By default an embedded ``LocalCluster`` of one single-threaded worker process per core (or
``workers``); with ``scheduler="tcp://HOST:PORT"`` an existing cluster (``dask scheduler`` and
``dask worker`` on any machines that can import stillframe). A task that raises is recorded with
its error and the others go on; Ctrl-C cancels what has not finished and keeps what has. Progress
(done / running / failed) goes to stderr.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from stillframe.errors import InputError

CONNECT_TIMEOUT_S = 10.0


@dataclass
class Outcome:
    """One task: its index in the input, its value, or the error it raised (type and text)."""

    index: int
    value: Any = None
    error: str | None = None
    error_type: str | None = None


@dataclass
class Execution:
    """The finished tasks in input order; ``interrupted`` when Ctrl-C stopped the rest."""

    outcomes: list[Outcome] = field(default_factory=list)
    interrupted: bool = False
    workers: int = 0
    address: str = ""
    wall_s: float = 0.0

    @property
    def failed(self) -> int:
        return sum(o.error is not None for o in self.outcomes)


def check_workers(workers: int | None) -> int:
    """The number of local workers: ``workers`` or one per core; InputError below 1."""
    if workers is None:
        return os.cpu_count() or 1
    if workers < 1:
        raise InputError(f"--workers {workers}: must be at least 1")
    return workers


@contextmanager
def _workers_ignore_ctrl_c() -> Iterator[None]:
    """Ignore SIGINT while the local workers start: they inherit it (Python keeps an ignored
    SIGINT), so Ctrl-C reaches only this process, which then stops them in order."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _connect(scheduler: str | None, workers: int | None) -> tuple[Any, Any]:
    """A Client on the given scheduler, or on a new LocalCluster (returned for closing)."""
    from distributed import Client, LocalCluster

    if scheduler is None:
        with _workers_ignore_ctrl_c():
            cluster = LocalCluster(n_workers=check_workers(workers), threads_per_worker=1,
                                   processes=True, dashboard_address="127.0.0.1:0",
                                   silence_logs=logging.CRITICAL)
        return Client(cluster), cluster
    if not scheduler.startswith(("tcp://", "tls://", "inproc://", "ws://", "wss://")):
        raise InputError(f"--scheduler {scheduler}: expected an address like tcp://HOST:8786")
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"--scheduler {scheduler}: no scheduler with workers there "
                         f"({type(exc).__name__})") from None
    return client, None


class _Progress:
    """``label: done/total done (failed failed), running running`` on one stderr line."""

    def __init__(self, label: str, total: int, client: Any, show: bool) -> None:
        self.label, self.total, self.client, self.show = label, total, client, show
        self.last = 0.0

    def running(self) -> int:
        return sum(len(keys) for keys in self.client.processing().values())

    def __call__(self, done: int, failed: int, final: bool = False) -> None:
        now = time.monotonic()
        if not self.show or (not final and now - self.last < 0.5):
            return
        self.last = now
        running = 0 if final else self.running()
        print(f"\r{self.label}: {done}/{self.total} done ({failed} failed), {running} running  ",
              end="\n" if final else "", file=sys.stderr, flush=True)


def run_tasks(fn: Callable[[Any], Any], items: Sequence[Any], *, workers: int | None = None,
              scheduler: str | None = None, label: str = "runs",
              progress: bool = True) -> Execution:
    """``fn(item)`` for every item on Dask; ``fn`` must be importable by the workers."""
    from distributed import as_completed

    started = time.perf_counter()
    client, cluster = _connect(scheduler, workers)
    execution = Execution(workers=len(client.scheduler_info()["workers"]),
                          address=client.scheduler.address)
    futures = client.map(fn, list(items), pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    show = _Progress(label, len(futures), client, progress)
    finished: list[Outcome] = []
    try:
        for future in as_completed(futures):
            i = index[future.key]
            if future.status == "finished":
                finished.append(Outcome(i, future.result()))
            else:
                exc = future.exception()
                finished.append(Outcome(i, error=str(exc) or repr(exc),
                                        error_type=type(exc).__name__))
            future.release()
            show(len(finished), sum(o.error is not None for o in finished))
    except KeyboardInterrupt:
        execution.interrupted = True
        client.cancel(futures)
    finally:
        show(len(finished), sum(o.error is not None for o in finished), final=True)
        client.close()
        if cluster is not None:
            cluster.close()
    execution.outcomes = sorted(finished, key=lambda o: o.index)
    execution.wall_s = time.perf_counter() - started
    return execution


def mapper(workers: int | None, scheduler: str | None, label: str
           ) -> Callable[[Callable[[Any], Any], Sequence[Any]], list[Any]] | None:
    """A ``map(fn, items)`` on Dask for the benchmark sweeps (None: neither option given, so
    they stay serial in this process). Every task must succeed: the first error is raised as
    one line, Ctrl-C as KeyboardInterrupt."""
    if workers is None and scheduler is None:
        return None

    def run(fn: Callable[[Any], Any], items: Sequence[Any]) -> list[Any]:
        execution = run_tasks(fn, items, workers=workers, scheduler=scheduler, label=label,
                              progress=sys.stderr.isatty())
        if execution.interrupted:
            raise KeyboardInterrupt
        for o in execution.outcomes:
            if o.error is not None:
                raise InputError(f"{label}: {execution.failed} of {len(items)} tasks failed; "
                                 f"task {o.index}: {o.error_type}: {o.error}")
        return [o.value for o in execution.outcomes]

    return run
