"""A settled machine before each real-time run of a benchmark, and the CPU others used during it.

``stillframe bench loop`` runs several real-time runs one after the other; each must start where
the last one left nothing behind. :func:`settle` does, before each run: checks that the
previous run's children are gone (reaped, not only signalled), collects this process's garbage
(the previous bag was read here), flushes the dirty pages the previous run wrote (``os.sync``: the
kernel writes them back 30 s later otherwise, during the next run), then waits until the machine
is idle at normal priority, and says what it found. :class:`CpuShare` counts the CPU the rest of
the machine used during a run: the kernel's busy time (``/proc/stat``) less this process's and its
reaped children's (``getrusage``), and of it what niced tasks used, so a run disturbed by another
job is shown as such in the table.
"""

from __future__ import annotations

import gc
import os
import resource
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: the idle check's window [s]
IDLE_WINDOW_S = 1.0
#: the machine counts as settled below this many CPUs busy at normal priority (not niced)
IDLE_BUSY_CPUS = 0.3
#: how long :func:`settle` waits for the machine to settle before it starts the run anyway
SETTLE_TIMEOUT_S = 15.0
#: how long the previous run's children may take to be reaped
REAP_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class CpuTimes:
    """The machine's CPU time [s] from ``/proc/stat``'s first line: busy (user, nice, system,
    irq, softirq, steal), the niced tasks' user time (``nice``), and the total."""

    busy_s: float
    nice_s: float
    total_s: float

    @classmethod
    def parse(cls, line: str) -> CpuTimes:
        """The machine's CPU times [s] from the ``cpu`` line of ``/proc/stat`` (clock ticks over
        ``SC_CLK_TCK``): busy, niced and total."""
        user, nice, system, idle, iowait, irq, softirq, steal = (
            int(v) / os.sysconf("SC_CLK_TCK") for v in line.split()[1:9])
        busy = user + nice + system + irq + softirq + steal
        return cls(busy, nice, busy + idle + iowait)


def cpu_times(stat: Path = Path("/proc/stat")) -> CpuTimes:
    """The machine's CPU times now, from ``stat`` (``/proc/stat``)."""
    with open(stat) as f:
        return CpuTimes.parse(f.readline())


def children_cpu_s() -> float:
    """The CPU time (user + system) of this process's reaped children."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return children.ru_utime + children.ru_stime


def own_cpu_s() -> float:
    """This process's and its reaped children's CPU time (user + system)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    return own.ru_utime + own.ru_stime + children_cpu_s()


def busy_cpus(before: CpuTimes, after: CpuTimes, ncpu: int) -> tuple[float, float]:
    """CPUs busy between two readings, at normal priority and niced (each in CPUs)."""
    total = after.total_s - before.total_s
    if total <= 0:
        return 0.0, 0.0
    nice = (after.nice_s - before.nice_s) / total * ncpu
    return (after.busy_s - before.busy_s) / total * ncpu - nice, nice


class CpuShare:
    """The CPU the rest of the machine used while the block ran (:meth:`stop`): busy time less
    this process's and its reaped children's, in CPUs, and of it the niced tasks' user time."""

    def __init__(self, times: Callable[[], CpuTimes] = cpu_times,
                 own: Callable[[], float] = own_cpu_s,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._times, self._own, self._clock = times, own, clock
        self._start = (times(), own(), clock())

    def stop(self) -> dict[str, float]:
        """How many CPUs other processes kept busy since the start (``others_cpus``), and how many
        of them at a lower priority (``others_niced_cpus``): the machine's busy time less this
        process's, over the wall time."""
        t0, own0, wall0 = self._start
        t1, own1, wall1 = self._times(), self._own(), self._clock()
        wall = max(wall1 - wall0, 1e-9)
        others = (t1.busy_s - t0.busy_s - (own1 - own0)) / wall
        return {"others_cpus": max(others, 0.0),
                "others_niced_cpus": min((t1.nice_s - t0.nice_s) / wall, max(others, 0.0))}


def live_children(pid: int | None = None, proc: Path = Path("/proc")) -> list[tuple[int, str]]:
    """The processes whose parent is ``pid`` (this process): (pid, name), zombies included."""
    pid = os.getpid() if pid is None else pid
    found = []
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            text = (entry / "stat").read_text()
        except OSError:
            continue
        name, _, rest = text[text.index("(") + 1:].rpartition(")")
        if int(rest.split()[1]) == pid:
            found.append((int(entry.name), name))
    return found


@dataclass
class Settled:
    """What :func:`settle` found: the machine's CPUs busy at normal priority and niced in the
    last window, the load average, the seconds waited, whether it settled, children left."""

    busy_cpus: float
    niced_cpus: float
    load_1min: float
    waited_s: float
    settled: bool
    children: list[tuple[int, str]]

    def text(self) -> str:
        """One line for the report: settled or not, the CPUs busy at normal priority and niced, the
        load average, and the children still running."""
        left = (f"; children still running: {', '.join(f'{n} ({p})' for p, n in self.children)}"
                if self.children else "")
        state = "settled" if self.settled else f"NOT settled after {self.waited_s:.0f} s"
        return (f"{state}: {self.busy_cpus:.2f} CPUs busy at normal priority, "
                f"{self.niced_cpus:.2f} niced, load {self.load_1min:.2f}{left}")

    def figures(self) -> dict[str, Any]:
        """The same as JSON fields of the benchmark's document (``before_*``, ``settled``,
        ``settle_wait_s``)."""
        return {"before_busy_cpus": self.busy_cpus, "before_niced_cpus": self.niced_cpus,
                "before_load_1min": self.load_1min, "settled": self.settled,
                "settle_wait_s": self.waited_s}


def settle(*, timeout_s: float = SETTLE_TIMEOUT_S, window_s: float = IDLE_WINDOW_S,
           limit_cpus: float = IDLE_BUSY_CPUS,
           times: Callable[[], CpuTimes] = cpu_times,
           sleep: Callable[[float], None] = time.sleep,
           children: Callable[[], list[tuple[int, str]]] = live_children,
           sync: Callable[[], None] = os.sync) -> Settled:
    """Wait for the previous run's children to be reaped, collect garbage, flush dirty pages,
    then take the machine's busy CPUs over ``window_s`` until fewer than ``limit_cpus`` are busy
    at normal priority or ``timeout_s`` passed (the run starts either way; the result says)."""
    ncpu = os.cpu_count() or 1
    waited = 0.0
    while (left := children()) and waited < REAP_TIMEOUT_S:
        sleep(0.1)
        waited += 0.1
    gc.collect()
    sync()
    waited = 0.0
    while True:
        before = times()
        sleep(window_s)
        waited += window_s
        busy, niced = busy_cpus(before, times(), ncpu)
        if busy < limit_cpus or waited >= timeout_s:
            break
    return Settled(busy, niced, os.getloadavg()[0], waited, busy < limit_cpus, left)
