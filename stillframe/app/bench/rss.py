"""Memory over a long run: resident set sizes sampled against sim time, and their growth after
warm-up.

The simulator keeps its histories for the evaluation at the end (per sample a row of 12 values,
per integrator step a row of 7, preallocated for the scene's duration, so the pages are touched
as the run goes): its RSS grows by design by :func:`history_bytes`. Growth is reported as it is
and, for the simulator, net of that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

#: float64 values the simulator stores per sample (sim_node's rows) and per integrator step
#: (:class:`stillframe.plant.frame_plant.FramePlant` fine history).
SAMPLE_ROW, STEP_ROW = 12, 7


def rss_bytes(pid: int) -> int | None:
    """The resident set size of process ``pid`` [bytes] (``VmRSS`` in /proc), None if gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    for line in status.splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    return None


def history_bytes(sim_s: float, period_s: float, substeps: int) -> int:
    """Bytes of history the simulator has written by sim time ``sim_s``."""
    samples = round(sim_s / period_s)
    return 8 * samples * (SAMPLE_ROW + substeps * STEP_ROW)


@dataclass
class RssLog:
    """RSS of each named process against sim time."""

    samples: dict[str, list[tuple[float, int]]] = field(default_factory=dict)

    def add(self, name: str, sim_s: float, rss: int) -> None:
        """Record process ``name``'s resident set size ``rss`` [bytes] at sim time ``sim_s`` [s]."""
        self.samples.setdefault(name, []).append((sim_s, rss))

    def growth(self, name: str, warmup_s: float, by_design: tuple[float, int] | None = None,
               until_s: float = math.inf) -> dict[str, float]:
        """RSS at the first sample at or after ``warmup_s`` of sim time, at the last before
        ``until_s``, the peak, and the growth from the first to the last [%]; ``by_design`` =
        (period [s], substeps) also gives the growth net of :func:`history_bytes`."""
        after = [(t, r) for t, r in self.samples.get(name, []) if warmup_s <= t < until_s]
        if len(after) < 2:
            return {}
        (t0, r0), (t1, r1) = after[0], after[-1]
        out = {"warm_sim_s": t0, "end_sim_s": t1, "warm_mib": r0 / 2**20, "end_mib": r1 / 2**20,
               "peak_mib": max(r for _, r in after) / 2**20,
               "growth_pct": 100.0 * (r1 - r0) / r0, "samples": len(after)}
        if by_design is not None:
            period, substeps = by_design
            net = r1 - r0 - (history_bytes(t1, period, substeps) - history_bytes(t0, period,
                                                                                 substeps))
            out["history_mib"] = (r1 - r0 - net) / 2**20
            out["net_growth_pct"] = 100.0 * net / r0
        return out
