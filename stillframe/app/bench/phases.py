"""The loop nodes' phase rings (:mod:`stillframe.node_runtime.phase_timing`) joined into each
sample's path: the cost of every hop, a latency histogram, and the worst samples explained.

Each ring's file names its columns (its marks and counters, written by
:meth:`stillframe.node_runtime.phase_timing.PhaseLog.write`). The three nodes' rows join by the
sample's stamp; their marks are times of one monotonic clock,
so a hop between two processes is the difference of two marks of different nodes. One sample's
path (:data:`PATH`) runs from sim_node's wake-up through the estimator and the controller back to
sim_node's next wake-up; the successive differences add up to the sample.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.bench.latency import LatencyLog
from stillframe.text_table import format_table

SIM, EST, CTL = "sim_node", "estimator_node", "controller_node"

#: one sample's path: (who, what, from (node, mark), to (node, mark)); ``next_woke``: sim_node's
#: wake-up for the next sample
PATH: tuple[tuple[str, str, tuple[str, str], tuple[str, str]], ...] = (
    (SIM, "plant sample", (SIM, "woke"), (SIM, "sampled")),
    (SIM, "serialize the sample's messages", (SIM, "sampled"), (SIM, "serialized")),
    (f"{SIM} -> {EST}", "write, wake-up, take, read the first message",
     (SIM, "serialized"), (EST, "first_in")),
    (EST, "take and read the stamp's other messages", (EST, "first_in"), (EST, "ready")),
    (EST, "filter step", (EST, "ready"), (EST, "computed")),
    (EST, "serialize estimate + covariance", (EST, "computed"), (EST, "serialized")),
    (f"{EST} -> {CTL}", "write, wake-up, take, read the estimate",
     (EST, "serialized"), (CTL, "estimate_in")),
    (CTL, "match the load cell", (CTL, "estimate_in"), (CTL, "ready")),
    (CTL, "control law", (CTL, "ready"), (CTL, "computed")),
    (CTL, "serialize the command", (CTL, "computed"), (CTL, "serialized")),
    (f"{CTL} -> {SIM}", "write, wake-up, take, read the command",
     (CTL, "serialized"), (SIM, "command_in")),
    (SIM, "rest of the wait (other commands, the gate)", (SIM, "command_in"), (SIM, "answered")),
    (SIM, "plant advance", (SIM, "answered"), (SIM, "advanced")),
    (SIM, "topics off the path, decimated taps", (SIM, "advanced"), (SIM, "tapped")),
    (SIM, "collector", (SIM, "tapped"), (SIM, "collected")),
    (SIM, "status", (SIM, "collected"), (SIM, "done")),
    (SIM, "to the next sample", (SIM, "done"), (SIM, "next_woke")),
)
#: work beside the path (a writer goes on writing after its reader woke)
BESIDE: tuple[tuple[str, str, tuple[str, str], tuple[str, str]], ...] = (
    (SIM, "wake-up lateness (real time: after the due time)", (SIM, "due"), (SIM, "woke")),
    (SIM, "write /clock and the sample's messages", (SIM, "serialized"), (SIM, "written")),
    (EST, "write estimate + covariance", (EST, "serialized"), (EST, "written")),
    (EST, "collector", (EST, "written"), (EST, "collected")),
    (EST, "status", (EST, "collected"), (EST, "done")),
    (CTL, "write the command", (CTL, "serialized"), (CTL, "written")),
    (CTL, "collector", (CTL, "written"), (CTL, "collected")),
    (CTL, "status", (CTL, "collected"), (CTL, "done")),
)
#: the latency histogram's bin edges [µs]
HISTOGRAM_US = (0, 100, 200, 300, 400, 500, 600, 700, 800, 900, 1000, 1500, 2000, 5000, 10_000,
                math.inf)
#: a phase of a worst sample is named when it took this much [µs] more than its median
EXCESS_US = 20.0


@dataclass
class NodeRing:
    """One node's rows, by column name (``stamp``, the marks, the counters), and its facts."""

    meta: dict[str, Any]
    columns: dict[str, np.ndarray]

    @classmethod
    def load(cls, path: Path) -> NodeRing:
        with np.load(path) as data:
            rows, meta = data["rows"], json.loads(str(data["meta"]))
        names = ["stamp", *meta["marks"], *meta["counters"]]
        return cls(meta, {name: rows[:, i] for i, name in enumerate(names)})


def load(directory: Path) -> dict[str, NodeRing]:
    """The rings written to ``directory`` by node name (those present)."""
    return {path.stem: NodeRing.load(path) for path in sorted(directory.glob("*.npz"))}


class SamplePaths:
    """Every sample's marks of every node, joined by stamp (sim_node's samples)."""

    def __init__(self, rings: dict[str, NodeRing]) -> None:
        self.rings = rings
        sim = rings[SIM].columns
        self.stamps = sim["stamp"]
        self.marks: dict[tuple[str, str], np.ndarray] = {}
        self.counts: dict[tuple[str, str], np.ndarray] = {}
        for node, ring in rings.items():
            at = self._rows_of(ring.columns["stamp"])
            counters = ring.meta["counters"]
            for name in (*ring.meta["marks"], *counters):
                column = ring.columns[name]
                picked = np.where(at >= 0, column[np.maximum(at, 0)], 0)
                if name in counters:      # the sample's own: since the node's row before
                    total = np.maximum.accumulate(column)   # a row not closed holds 0
                    own = total - np.concatenate([total[:1], total[:-1]])
                    picked = np.where(at >= 0, own[np.maximum(at, 0)], 0)
                    self.counts[node, name] = picked
                else:
                    self.marks[node, name] = picked
        woke = sim["woke"]
        self.marks[SIM, "next_woke"] = np.concatenate([woke[1:], [0]])

    def _rows_of(self, stamps: np.ndarray) -> np.ndarray:
        """For each sim_node stamp, the row of ``stamps`` with it (the last such), or -1."""
        order = np.argsort(stamps, kind="stable")
        ordered = stamps[order]
        pos = np.searchsorted(ordered, self.stamps, side="right") - 1
        found = (pos >= 0) & (ordered[np.maximum(pos, 0)] == self.stamps)
        return np.where(found, order[np.maximum(pos, 0)], -1)

    def span_us(self, start: tuple[str, str], end: tuple[str, str]) -> np.ndarray:
        """Per sample, ``end`` − ``start`` [µs]; NaN where either mark is missing, and for a hop
        between two nodes where ``end`` came first: the marks are then of two messages, not
        one (the simulator took the controller watchdog's zero for that stamp, which the
        controller's ring does not time, before the law's command was written)."""
        a = self.marks.get(start)
        b = self.marks.get(end)
        if a is None or b is None:
            return np.full(len(self.stamps), np.nan)
        ok = (a > 0) & (b > 0)
        if start[0] != end[0]:
            ok &= b >= a
        return np.where(ok, (b - a) * 1e-3, np.nan)

    def table(self, steps: tuple[tuple[str, str, tuple[str, str], tuple[str, str]], ...]
              ) -> list[dict[str, Any]]:
        """Per step: the samples that have it, mean, p50, p99 and max [µs]."""
        out = []
        for who, what, start, end in steps:
            span = self.span_us(start, end)
            span = span[np.isfinite(span)]
            if not span.size:
                continue
            p50, p99 = np.percentile(span, (50, 99))
            out.append({"who": who, "what": what, "samples": int(span.size),
                        "mean_us": float(span.mean()), "p50_us": float(p50),
                        "p99_us": float(p99), "max_us": float(span.max())})
        return out

    def explain(self, stamp: int, medians: dict[str, float]) -> dict[str, Any]:
        """Sample ``stamp``: the steps of its path (and beside it) that took
        :data:`EXCESS_US` more than their median, largest first, and what each node's main
        thread met in it (page faults, involuntary context switches, more waits than usual: a
        call that blocked)."""
        hits = np.nonzero(self.stamps == stamp)[0]
        if not hits.size:
            return {"stamp": stamp, "phases": [], "kernel": [], "found": False}
        i = int(hits[-1])
        phases = []
        for who, what, start, end in (*PATH, *BESIDE):
            span = float(self.span_us(start, end)[i])
            median = medians.get(f"{who}: {what}", math.nan)
            if math.isfinite(span) and span - median >= EXCESS_US:
                phases.append({"who": who, "what": what, "us": span, "median_us": median})
        phases.sort(key=lambda p: p["median_us"] - p["us"])
        kernel = []
        for node, ring in self.rings.items():
            counts = {name: int(self.counts[node, name][i]) for name in ring.meta["counters"]}
            fifo = ring.meta.get("sched_policy") == 1
            usual_waits = int(np.median(self.counts[node, "nvcsw"]))
            facts = [f"{counts['majflt']} major page faults" if counts["majflt"] else "",
                     f"{counts['minflt']} minor page faults" if counts["minflt"] else "",
                     (f"{counts['nivcsw']} involuntary context switches"
                      + (" at SCHED_FIFO (a higher priority, or the kernel's RT throttling)"
                         if fifo else "")) if counts["nivcsw"] else "",
                     (f"{counts['nvcsw']} waits (voluntary switches; usually {usual_waits})"
                      if counts["nvcsw"] > usual_waits else "")]
            if text := ", ".join(f for f in facts if f):
                kernel.append({"node": node, "text": text, **counts})
        return {"stamp": stamp, "phases": phases, "kernel": kernel, "found": True}


def latency_log(rings: dict[str, NodeRing], period_ns: int) -> LatencyLog:
    """Each sample's latency as the nodes' rings time it: from sim_node's first write of the
    sample (its ``serialized`` mark, just before ``/clock``) to the controller's write of the
    command (its ``serialized`` mark). The same span an observer's DDS source timestamps give
    (the floor-1 IMU's write to the command's), begun one write earlier; with no observer
    taking the messages. Empty without sim_node's or the controller's ring."""
    log = LatencyLog(period_ns)
    if SIM not in rings or CTL not in rings:
        return log
    for node, add in ((SIM, log.on_sample), (CTL, log.on_command)):
        columns = rings[node].columns
        for stamp, at in zip(columns["stamp"].tolist(), columns["serialized"].tolist(),
                             strict=True):
            if at:
                add(stamp, at)
    return log


def medians(paths: SamplePaths) -> dict[str, float]:
    """Each step's median [µs] by ``"who: what"``."""
    return {f"{row['who']}: {row['what']}": row["p50_us"]
            for row in paths.table((*PATH, *BESIDE))}


def histogram(latency_us: np.ndarray) -> list[dict[str, Any]]:
    """Samples per latency bin (:data:`HISTOGRAM_US`), with their share."""
    counts, _ = np.histogram(latency_us, bins=np.array(HISTOGRAM_US, dtype=float))
    total = max(int(latency_us.size), 1)
    return [{"from_us": lo, "to_us": hi, "samples": int(n), "pct": 100.0 * n / total}
            for lo, hi, n in zip(HISTOGRAM_US[:-1], HISTOGRAM_US[1:], counts, strict=True)]


def worst(latency_by_stamp: dict[int, float], paths: SamplePaths | None,
          count: int = 10) -> list[dict[str, Any]]:
    """The ``count`` samples of the largest latency [µs], each explained
    (:meth:`SamplePaths.explain`) when the rings are there."""
    ranked = sorted(latency_by_stamp.items(), key=lambda item: -item[1])[:count]
    typical = medians(paths) if paths is not None else {}
    out = []
    for stamp, latency in ranked:
        explained = (paths.explain(stamp, typical) if paths is not None
                     else {"stamp": stamp, "phases": [], "kernel": [], "found": False})
        out.append({"latency_us": latency, **explained})
    return out


def rt_budget(rings: dict[str, NodeRing]) -> str:
    """The kernel's RT throttling budget as the nodes read it: one line."""
    meta = next(iter(rings.values())).meta if rings else {}
    runtime, period = meta.get("sched_rt_runtime_us"), meta.get("sched_rt_period_us")
    if runtime is None or period is None:
        return "RT throttling: unknown (no /proc/sys/kernel/sched_rt_*)"
    if runtime < 0:
        return "RT throttling: off (sched_rt_runtime_us = -1)"
    return (f"RT throttling: real-time threads may run {runtime} of every {period} us per CPU "
            f"(/proc/sys/kernel/sched_rt_*); a SCHED_FIFO thread past it waits "
            f"{(period - runtime) / 1000:g} ms")


# -- as text ------------------------------------------------------------------------------------
def path_table(path: list[dict[str, Any]], beside: list[dict[str, Any]],
               floor_rtt_us: float | None = None) -> str:
    """Each step along the sample's path (their means add up to the sample) and beside it; with
    ``floor_rtt_us`` (a raw Cyclone round trip measured in the same run) each hop between
    processes against half of it."""
    def row(r: dict[str, Any], on_path: bool) -> list[str]:
        hop = "->" in r["who"]
        floor = (f"{r['p50_us'] / (floor_rtt_us / 2):.1f}"
                 if hop and floor_rtt_us else "")
        return [r["who"], r["what"] + ("" if on_path else " (beside)"), f"{r['mean_us']:.1f}",
                f"{r['p50_us']:.1f}", f"{r['p99_us']:.1f}", f"{r['max_us']:.0f}", floor]

    total = sum(r["mean_us"] for r in path)
    lines = [format_table(
        ["who", "step", "mean [us]", "p50 [us]", "p99 [us]", "max [us]", "p50 / raw hop"],
        [row(r, True) for r in path] + [row(r, False) for r in beside])]
    lines.append(f"the path's means add up to {total:.0f} us a sample "
                 f"({1e6 / total:.0f} samples/s)" if total > 0 else "no sample on the path")
    if floor_rtt_us:
        lines.append(f"raw Cyclone floor, same run: round trip p50 {floor_rtt_us:.0f} us, so "
                     f"{1.5 * floor_rtt_us:.0f} us for the three hops of a sample "
                     f"({1e6 / (1.5 * floor_rtt_us):.0f} samples/s with no work at all)")
    return "\n".join(lines)


def histogram_text(bins: list[dict[str, Any]], width: int = 40) -> str:
    """The latency histogram, one line a bin, with a bar."""
    top = max((b["samples"] for b in bins), default=0) or 1
    lines = []
    for b in bins:
        label = (f"{b['from_us']:>6g} - {b['to_us']:<6g} us" if math.isfinite(b["to_us"])
                 else f"{b['from_us']:>6g} us and more ")
        bar = "#" * math.ceil(width * b["samples"] / top) if b["samples"] else ""
        lines.append(f"{label} {b['samples']:>7} {b['pct']:7.3f} % {bar}")
    return "\n".join(lines)


def worst_text(samples: list[dict[str, Any]]) -> str:
    """The worst samples, each with the steps that took longer than usual and what the kernel
    says of each node's thread in it."""
    rows = []
    for s in samples:
        steps = "; ".join(f"{p['who']}: {p['what']} {p['us']:.0f} us (median "
                          f"{p['median_us']:.0f})" for p in s["phases"][:3])
        kernel = "; ".join(f"{k['node']}: {k['text']}" for k in s["kernel"])
        rows.append([f"{s['stamp'] * 1e-9:.3f}", f"{s['latency_us']:.0f}",
                     steps or ("-" if s["found"] else "not in sim_node's ring"), kernel or "-"])
    return format_table(["t [s]", "latency [us]", "longer than usual", "kernel"], rows)
