"""The per-sample phase ring (stillframe.node_runtime.phase_timing): rows in order once it wraps,
marks where they were made, the thread's counters against conditions the test forces (fresh
pages touched, a SCHED_FIFO process taking the CPU), and no allocation per sample."""

from __future__ import annotations

import gc
import mmap
import os
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from stillframe.app.bench.phases import NodeRing
from stillframe.node_runtime import phase_timing
from stillframe.node_runtime.phase_timing import COUNTERS, PhaseLog

MARKS = ("woke", "computed", "done")


def test_rows_are_kept_oldest_first_once_the_ring_wraps() -> None:
    log = PhaseLog("n", MARKS, capacity=4)
    slots = log.slots
    for k in range(6):
        log.begin(1000 + k)
        log.mark_at(slots["woke"], 10 * k + 1)
        if k != 4:                       # sample 4 never computed: its slot stays 0
            log.mark_at(slots["computed"], 10 * k + 2)
        log.end(slots["done"])
    table = log.table()
    assert table.shape == (4, 1 + len(MARKS) + len(COUNTERS))
    assert table[:, 0].tolist() == [1002, 1003, 1004, 1005]
    assert table[:, 1].tolist() == [21, 31, 41, 51]
    assert table[:, 2].tolist() == [22, 32, 0, 52]
    assert (table[:, 3] > 0).all() and log.ended_ns == table[-1, 3]


def test_a_mark_outside_a_row_and_a_disabled_log_write_nothing() -> None:
    log = PhaseLog("n", MARKS, capacity=4)
    log.mark(log.slots["woke"])               # no row open
    assert log.table().shape[0] == 0
    off = PhaseLog("n", MARKS, enabled=False)
    off.begin(5)
    off.mark(1)
    off.end(3)
    assert off.rows == 0 and off.table().shape[0] == 0


def test_minor_page_faults_of_a_sample_count_the_fresh_pages_it_touched() -> None:
    """256 pages of a fresh anonymous mapping, each written once inside one row: the kernel
    maps each on its first touch, a minor fault each (at least 256; the interpreter may add a
    few of its own)."""
    pages = 256
    log = PhaseLog("n", MARKS, capacity=8)
    log.begin(0)
    log.end(3)
    area = mmap.mmap(-1, pages * mmap.PAGESIZE)
    log.begin(1)
    for page in range(pages):
        area[page * mmap.PAGESIZE] = 1
    log.end(3)
    area.close()
    minflt = log.table()[:, 1 + len(MARKS) + COUNTERS.index("minflt")]
    assert pages <= minflt[1] - minflt[0] < pages + 64


FIFO_HOG = """
import os, sys, time
os.sched_setaffinity(0, {{{cpu}}})
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
print("ready", flush=True)
sys.stdin.readline()
end = time.monotonic() + 0.2
while time.monotonic() < end:
    pass
"""


@pytest.mark.skipif(os.geteuid() != 0, reason="SCHED_FIFO needs root")
def test_a_sample_preempted_by_a_fifo_process_counts_involuntary_switches() -> None:
    """This thread, busy on one CPU, and a SCHED_FIFO process on the same CPU that spins for
    0.2 s once told: the kernel must take the CPU from this thread while it is runnable, an
    involuntary context switch in that row (none needed in a row where nothing competes)."""
    cpu = min(os.sched_getaffinity(0))
    before = os.sched_getaffinity(0)
    hog = subprocess.Popen([sys.executable, "-c", FIFO_HOG.format(cpu=cpu)],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert hog.stdout.readline().strip() == "ready"
        os.sched_setaffinity(0, {cpu})
        log = PhaseLog("n", MARKS, capacity=8)
        log.begin(0)
        log.end(3)
        log.begin(1)
        hog.stdin.write("go\n")
        hog.stdin.flush()
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            pass
        log.end(3)
    finally:
        os.sched_setaffinity(0, before)
        hog.wait(timeout=30)
    nivcsw = log.table()[:, 1 + len(MARKS) + COUNTERS.index("nivcsw")]
    assert nivcsw[1] - nivcsw[0] >= 1


def test_no_allocation_per_sample() -> None:
    """Rows begun, marked and closed with the collector off: of the blocks phase_timing's code
    allocated in 10 or 50 000 rows, at most 3 are alive at the end, the integers the log holds
    between rows (``rows``, ``base``, ``ended_ns``), replaced each row. tracemalloc is filtered to
    that file, so the test process's other threads cannot count. Nothing is kept per row, the
    ring was allocated at start; a container made per row and left in a cycle would count
    50 000."""
    log = PhaseLog("n", MARKS, capacity=1 << 10)
    slots = log.slots
    here = tracemalloc.Filter(True, phase_timing.__file__)

    def rows(n: int) -> None:
        for k in range(n):
            log.begin(k)
            log.mark(slots["woke"])
            log.mark_at(slots["computed"], k)
            log.end(slots["done"])

    def growth(n: int) -> int:
        start = tracemalloc.take_snapshot().filter_traces([here])
        rows(n)
        end = tracemalloc.take_snapshot().filter_traces([here])
        return sum(stat.count_diff for stat in end.compare_to(start, "lineno"))

    rows(100)                                   # warm up (first calls, caches)
    gc.disable()
    tracemalloc.start()
    try:
        few, many = growth(10), growth(50_000)
    finally:
        tracemalloc.stop()
        gc.enable()
    assert few <= 3 and many <= 3


def test_the_ring_written_reads_back_by_name(tmp_path: Path) -> None:
    log = PhaseLog("estimator_node", MARKS, capacity=4)
    log.begin(7)
    log.mark_at(log.slots["woke"], 11)
    log.end(log.slots["done"])
    path = log.write(tmp_path, {"mode": "realtime"})
    assert path == tmp_path / "estimator_node.npz"
    ring = NodeRing.load(path)
    assert ring.meta["node"] == "estimator_node" and ring.meta["mode"] == "realtime"
    assert ring.meta["marks"] == list(MARKS) and ring.meta["pid"] == os.getpid()
    with open("/proc/sys/kernel/sched_rt_period_us") as f:
        assert ring.meta["sched_rt_period_us"] == int(f.read())
    assert ring.columns["stamp"].tolist() == [7] and ring.columns["woke"].tolist() == [11]
    assert np.all(ring.columns["minflt"] > 0)
