"""Busy loops beside a benchmark: the ordinary load of a workstation that does other things.

Each loop is ``sh -c 'while :; do :; done'`` in its own session, at the default priority, as a
user's build or second analysis would be; all of them are killed when the block ends.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
from collections.abc import Iterator

BUSY_LOOP = ("sh", "-c", "while :; do :; done")


@contextlib.contextmanager
def busy_loops(count: int) -> Iterator[list[int]]:
    """``count`` busy loops running while the block runs; their process ids."""
    procs = [subprocess.Popen(BUSY_LOOP, start_new_session=True, stdin=subprocess.DEVNULL,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for _ in range(count)]
    try:
        yield [p.pid for p in procs]
    finally:
        for proc in procs:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
        for proc in procs:
            proc.wait(timeout=30)
