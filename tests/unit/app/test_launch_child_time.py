"""The launcher's lifecycle timeout counts the time the machine gave a child, not wall time:
a child that sleeps (or hangs) uses its time up, a child the machine does not run keeps it.
Both conditions are forced: the starved child runs at SCHED_IDLE on the one CPU a busy loop
holds, so it can make no progress whatever the machine's speed."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from stillframe.app.launcher import Child

BUSY = [sys.executable, "-c", "while True: pass"]


def _child(argv: list[str]) -> Child:
    return Child("probe", subprocess.Popen(argv))


def _stop(*children: Child) -> None:
    for child in children:
        child.proc.kill()
        child.proc.wait()


def test_a_sleeping_child_is_given_its_wall_time() -> None:
    child = _child([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        time.sleep(1.0)
        wall = (time.monotonic_ns() - child.started_ns) * 1e-9
        assert child.time_given_s() == pytest.approx(wall, rel=0.1)
    finally:
        _stop(child)


@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE") or not os.path.exists("/proc/self/schedstat"),
                    reason="Linux scheduling classes and the kernel's schedstat")
def test_a_child_the_machine_does_not_run_is_not_given_the_time() -> None:
    cpu = min(os.sched_getaffinity(0))
    hog = _child(BUSY)
    starved = _child(BUSY)
    try:
        os.sched_setaffinity(hog.pid, {cpu})
        os.sched_setaffinity(starved.pid, {cpu})
        os.sched_setscheduler(starved.pid, os.SCHED_IDLE, os.sched_param(0))
        time.sleep(0.2)
        before = starved.time_given_s()
        time.sleep(2.0)
        # SCHED_IDLE (weight 3) beside a runnable normal task on its only CPU (weight 1024 at
        # nice 0, 15 at nice 19): at most 3 / 18 of the 2 s
        assert starved.time_given_s() - before < 0.5
    finally:
        _stop(hog, starved)
