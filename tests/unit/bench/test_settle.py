"""``bench loop``'s settled start (issue 32): the previous run's children reaped, dirty pages
flushed, the machine idle at normal priority before the next run, and the CPU the rest of the
machine used during a run. The kernel's counters are faked, so each condition is forced."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from stillframe.app.bench.settle import (
    CpuShare,
    CpuTimes,
    Settled,
    busy_cpus,
    live_children,
    settle,
)

TICK = os.sysconf("SC_CLK_TCK")


def times(busy: float, nice: float, total: float) -> CpuTimes:
    return CpuTimes(busy, nice, total)


def test_proc_stat_line_is_split_into_busy_niced_and_total_time() -> None:
    # user nice system idle iowait irq softirq steal guest guest_nice
    t = CpuTimes.parse("cpu  100 40 30 500 20 5 3 2 0 0")
    assert t.busy_s == pytest.approx((100 + 40 + 30 + 5 + 3 + 2) / TICK)
    assert t.nice_s == pytest.approx(40 / TICK)
    assert t.total_s == pytest.approx((100 + 40 + 30 + 500 + 20 + 5 + 3 + 2) / TICK)


def test_busy_cpus_splits_normal_priority_from_niced() -> None:
    # 2 CPUs for 1 s: 2 CPU-seconds in all; 1.0 busy of which 0.4 niced
    normal, niced = busy_cpus(times(0, 0, 0), times(1.0, 0.4, 2.0), ncpu=2)
    assert (normal, niced) == (pytest.approx(0.6), pytest.approx(0.4))
    assert busy_cpus(times(1, 1, 1), times(1, 1, 1), ncpu=2) == (0.0, 0.0)


class FakeMachine:
    """/proc/stat readings that go ``busy`` normal-priority CPUs per window, one value per
    window, on 2 CPUs; children that are reaped after ``reaped_after`` looks."""

    def __init__(self, busy: list[float], children: int = 0) -> None:
        self.busy = busy
        self.t = times(0.0, 0.0, 0.0)
        self.window = 0
        self.slept: list[float] = []
        self.synced = 0
        self.looks = children

    def times(self) -> CpuTimes:
        return self.t

    def sleep(self, s: float) -> None:
        self.slept.append(s)
        if s >= 1.0:        # an idle-check window: 2 CPU-seconds pass
            b = self.busy[min(self.window, len(self.busy) - 1)]
            self.t = times(self.t.busy_s + b + 0.5, self.t.nice_s + 0.5, self.t.total_s + 2.0)
            self.window += 1

    def children(self) -> list[tuple[int, str]]:
        if self.looks:
            self.looks -= 1
            return [(4242, "python3")]
        return []

    def sync(self) -> None:
        self.synced += 1

    def settle(self, timeout_s: float = 15.0) -> Settled:
        return settle(timeout_s=timeout_s, window_s=1.0, limit_cpus=0.3, times=self.times,
                      sleep=self.sleep, children=self.children, sync=self.sync)


def test_settle_waits_for_the_children_and_for_an_idle_window() -> None:
    machine = FakeMachine(busy=[1.2, 0.9, 0.1], children=3)
    s = machine.settle()
    assert s.settled and s.children == []
    assert machine.slept[:3] == [0.1, 0.1, 0.1]         # three looks until the child was reaped
    assert machine.window == 3 and s.waited_s == 3.0     # two busy windows, then an idle one
    assert s.busy_cpus == pytest.approx(0.1) and s.niced_cpus == pytest.approx(0.5)
    assert machine.synced == 1
    assert s.text().startswith("settled: 0.10 CPUs busy at normal priority, 0.50 niced")


def test_settle_gives_up_after_its_timeout_and_says_so() -> None:
    machine = FakeMachine(busy=[1.5])
    s = machine.settle(timeout_s=4.0)
    assert not s.settled and s.waited_s == 4.0 and machine.window == 4
    assert s.text().startswith("NOT settled after 4 s: 1.50 CPUs busy")
    assert s.figures()["settled"] is False


def test_cpu_share_is_the_machines_busy_time_less_this_process_tree() -> None:
    readings = iter([times(10.0, 1.0, 50.0), times(16.0, 2.5, 70.0)])
    own = iter([3.0, 6.0])
    clock = iter([100.0, 110.0])
    share = CpuShare(times=lambda: next(readings), own=lambda: next(own),
                     clock=lambda: next(clock))
    # 6 CPU-s busy in 10 s, 3 of them ours: 0.3 CPUs others, 0.15 of it niced
    assert share.stop() == {"others_cpus": pytest.approx(0.3),
                            "others_niced_cpus": pytest.approx(0.15)}


def test_live_children_finds_a_real_child_until_it_is_reaped() -> None:
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert child.pid in [pid for pid, _ in live_children()]
    finally:
        child.kill()
        child.wait()
    assert child.pid not in [pid for pid, _ in live_children()]


def test_live_children_reads_the_parent_from_proc(tmp_path: Path) -> None:
    for pid, text in ((11, "11 (sim_node (x)) S 7 0"), (12, "12 (other) S 8 0"),
                      (13, "13 (recorder) Z 7 0")):
        (tmp_path / str(pid)).mkdir()
        (tmp_path / str(pid) / "stat").write_text(text)
    (tmp_path / "self").mkdir()
    assert sorted(live_children(7, proc=tmp_path)) == [(11, "sim_node (x)"), (13, "recorder")]
