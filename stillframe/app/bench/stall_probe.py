"""Whole-machine stalls during a real-time run, as ``cyclictest`` (Debian's rt-tests) sees them.

One cyclictest thread per CPU, pinned, at ``SCHED_FIFO`` 95 (above the loop nodes' 80), wakes
every millisecond; how late it wakes is the time its CPU ran nothing of higher priority in this
guest. A loop sample that misses its deadline while the probe on its CPU was late by as much was
stopped by the machine (the hypervisor or the kernel), not by the loop. ``--laptop`` keeps
cyclictest from holding ``/dev/cpu_dma_latency`` itself, so the probe does not change how the
CPUs idle (the ``cpu_latency`` practice does that, when asked).
"""

from __future__ import annotations

import contextlib
import json
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stillframe.errors import InputError

CYCLICTEST = "cyclictest"
PRIORITY = 95
INTERVAL_US = 1000
#: a probe wake this late [µs] or later counts as a stall (cyclictest's histogram ends here)
STALL_US = 1000


def command(json_path: Path) -> list[str]:
    """cyclictest: memory locked, one thread per CPU pinned to it, ``SCHED_FIFO``
    :data:`PRIORITY`, a wake every :data:`INTERVAL_US`, a histogram up to :data:`STALL_US`
    (later wakes are its overflows), results as JSON on SIGINT."""
    return [CYCLICTEST, "--mlockall", "--threads", "--affinity", f"--priority={PRIORITY}",
            f"--interval={INTERVAL_US}", "--quiet", "--laptop", f"--histogram={STALL_US}",
            f"--json={json_path}"]


def summary(result: dict[str, Any]) -> dict[str, Any]:
    """Per CPU: the latest wake [µs] and the wakes at least :data:`STALL_US` late (cycles the
    histogram does not hold); over all CPUs: the worst and the stalls."""
    cpus = []
    for thread in result["thread"].values():
        held = sum(int(n) for n in thread.get("histogram", {}).values())
        cpus.append({"cpu": thread["cpu"], "cycles": thread["cycles"], "max_us": thread["max"],
                     "stalls": thread["cycles"] - held})
    return {"probe_cpus": cpus, "probe_max_us": max(c["max_us"] for c in cpus),
            "probe_stalls": sum(c["stalls"] for c in cpus)}


@dataclass
class Probe:
    """A running probe: cyclictest's process id; :func:`summary` once it stopped."""

    pid: int
    summary: dict[str, Any] = field(default_factory=dict)


@contextlib.contextmanager
def stall_probe() -> Iterator[Probe]:
    """Run cyclictest while the block runs and fill the probe's summary when it ends.
    InputError when cyclictest is missing or may not run at ``SCHED_FIFO`` (it needs root)."""
    if shutil.which(CYCLICTEST) is None:
        raise InputError("stall probe: cyclictest is not installed (Debian: apt install rt-tests)")
    with tempfile.TemporaryDirectory(prefix="stillframe-probe-") as tmp:
        path = Path(tmp) / "cyclictest.json"
        proc = subprocess.Popen(command(path), stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)
        probe = Probe(proc.pid)
        try:
            yield probe
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
            _, errors = proc.communicate(timeout=30)
        if proc.returncode != 0 or not path.exists():
            raise InputError(f"stall probe: cyclictest failed (exit {proc.returncode}): "
                             f"{errors.strip() or 'no output'} (it needs root for "
                             f"SCHED_FIFO {PRIORITY} and mlockall)")
        probe.summary = summary(json.loads(path.read_text()))
