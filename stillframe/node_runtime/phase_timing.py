"""Per-sample phase timing of a loop node: :class:`PhaseLog`, on by default.

Every sample a node handles is one row of a ring preallocated at start (``array('q')``, no
allocation per sample): the sample's stamp, the monotonic time [ns] at the end of each of the
node's phases (:data:`MARKS`, in the order a sample passes them), and the node's main-thread
counters at the row's end (minor and major page faults, voluntary and involuntary context
switches: ``getrusage(RUSAGE_THREAD)`` into a preallocated struct). The monotonic clock is the
same in every process of a host, so the rows of the three nodes join by stamp into one sample's
path (:mod:`stillframe.app.bench.phases`). A mark not reached in a row stays 0.

With the ``phase_log`` parameter (a directory) the node writes its ring to ``<dir>/<node>.npz``
when it ends, with what the kernel says about its scheduling (:func:`sched_facts`).
"""

from __future__ import annotations

import ctypes
import json
import os
import time
from array import array
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["COUNTERS", "MARKS", "RING_SAMPLES", "PhaseLog", "sched_facts"]

#: the samples a ring holds: the last 65 s at 1 kHz
RING_SAMPLES = 1 << 16
#: the counters at each row's end, from ``struct rusage``
COUNTERS = ("minflt", "majflt", "nvcsw", "nivcsw")
#: each node's marks, in the order one sample passes them (a phase ends at its mark)
MARKS: dict[str, tuple[str, ...]] = {
    # due: when the sample was due (real time) or the previous sample ended (lock-step)
    "sim_node": ("due", "woke", "sampled", "serialized", "written", "command_in", "answered",
                 "advanced", "tapped", "collected", "done"),
    # first_in: the stamp's first message read; ready: its last input in, the stamp taken
    "estimator_node": ("first_in", "ready", "computed", "serialized", "written", "collected",
                       "done"),
    # estimate_in: the estimate read; ready: matched with its load cell
    "controller_node": ("estimate_in", "ready", "computed", "serialized", "written",
                        "collected", "done"),
}
_RUSAGE_THREAD = 1


class _Rusage(ctypes.Structure):
    _fields_ = [("utime", ctypes.c_long * 2), ("stime", ctypes.c_long * 2),
                *((name, ctypes.c_long) for name in (
                    "maxrss", "ixrss", "idrss", "isrss", "minflt", "majflt", "nswap", "inblock",
                    "oublock", "msgsnd", "msgrcv", "nsignals", "nvcsw", "nivcsw"))]


_libc = ctypes.CDLL(None, use_errno=True)
_getrusage = _libc.getrusage
_getrusage.argtypes = (ctypes.c_int, ctypes.c_void_p)
_getrusage.restype = ctypes.c_int


class PhaseLog:
    """The ring of one node (module docstring). ``marks`` names the columns after the stamp;
    ``enabled`` False makes every call return at once (a run without the instrument)."""

    def __init__(self, node: str, marks: Sequence[str], *, capacity: int = RING_SAMPLES,
                 enabled: bool = True) -> None:
        self.node = node
        self.marks = tuple(marks)
        self.enabled = enabled
        self.width = 1 + len(self.marks) + len(COUNTERS)
        self.capacity = capacity if enabled else 1
        self.ring = array("q", bytes(8 * self.width * self.capacity))
        self._blank = array("q", bytes(8 * (self.width - 1)))
        self.rows = 0                  # rows begun, ever
        self.base = -self.width        # the open row's first slot (none yet)
        self.ended_ns = 0              # when the last row closed
        self._usage = _Rusage()
        self._usage_at = ctypes.addressof(self._usage)
        self._clock = time.monotonic_ns

    @property
    def slots(self) -> dict[str, int]:
        """Each mark's slot in a row (for :meth:`mark`)."""
        return {mark: 1 + i for i, mark in enumerate(self.marks)}

    def begin(self, stamp_ns: int) -> None:
        """A new row for the sample stamped ``stamp_ns`` (the oldest row is overwritten once
        the ring is full)."""
        if not self.enabled:
            return
        base = (self.rows % self.capacity) * self.width
        ring = self.ring
        ring[base] = stamp_ns
        ring[base + 1:base + self.width] = self._blank
        self.base = base
        self.rows += 1

    def mark(self, slot: int) -> None:
        """The open row's ``slot`` (:meth:`index`) ends now."""
        if self.enabled and self.base >= 0:
            self.ring[self.base + slot] = self._clock()

    def mark_at(self, slot: int, at_ns: int) -> None:
        """The open row's ``slot`` ended at ``at_ns`` (a time the caller already read)."""
        if self.enabled and self.base >= 0:
            self.ring[self.base + slot] = at_ns

    def end(self, slot: int) -> None:
        """Mark ``slot`` now and close the row with the thread's counters."""
        if not self.enabled or self.base < 0:
            return
        ring, base = self.ring, self.base
        ring[base + slot] = self._clock()
        _getrusage(_RUSAGE_THREAD, self._usage_at)
        u, at = self._usage, base + 1 + len(self.marks)
        ring[at] = u.minflt
        ring[at + 1] = u.majflt
        ring[at + 2] = u.nvcsw
        ring[at + 3] = u.nivcsw
        self.ended_ns = ring[base + slot]
        self.base = -self.width

    def table(self) -> np.ndarray:
        """The rows kept, oldest first: (rows, 1 + marks + counters) int64."""
        kept = min(self.rows, self.capacity)
        rows = np.frombuffer(self.ring, dtype=np.int64).reshape(self.capacity, self.width)
        start = self.rows % self.capacity if self.rows > self.capacity else 0
        return np.concatenate([rows[start:kept], rows[:start]]) if start else rows[:kept].copy()

    def write(self, directory: str | Path, facts: dict[str, Any] | None = None) -> Path:
        """The rows kept and ``facts`` (plus :func:`sched_facts`) as ``<directory>/<node>.npz``."""
        path = Path(directory) / f"{self.node}.npz"
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"node": self.node, "pid": os.getpid(), "marks": list(self.marks),
                "counters": list(COUNTERS), "rows": self.rows, "capacity": self.capacity,
                **sched_facts(), **(facts or {})}
        np.savez(path, rows=self.table(), meta=np.array(json.dumps(meta)))
        return path


def _read(path: str) -> str | None:
    try:
        with open(path) as f:
            return f.read()
    except OSError:
        return None


def sched_facts() -> dict[str, Any]:
    """What the kernel tells about this process's scheduling: the RT throttling budget
    (``/proc/sys/kernel/sched_rt_runtime_us`` of every ``sched_rt_period_us``; -1: none), and
    the main thread's policy, priority and switches from ``/proc/self/sched``."""
    facts: dict[str, Any] = {}
    for key in ("sched_rt_runtime_us", "sched_rt_period_us"):
        text = _read(f"/proc/sys/kernel/{key}")
        facts[key] = int(text) if text is not None else None
    sched = _read("/proc/self/sched") or ""
    for line in sched.splitlines():
        name, sep, value = line.partition(":")
        if sep and name.strip() in ("policy", "prio", "nr_involuntary_switches",
                                    "nr_voluntary_switches", "se.nr_migrations"):
            facts[f"sched_{name.strip()}"] = int(float(value))
    return facts
