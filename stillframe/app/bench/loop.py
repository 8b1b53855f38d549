"""``stillframe bench loop``: the closed loop's latency in real time and its lock-step speed.

1. Real-time mode at 100 Hz and 1 kHz (the LQG scene with ``sensors.rate_hz`` and a matching
   ``integrator.dt``): sensor-stamp-to-command latency p50 / p99 / max and deadline misses, timed
   by the nodes' own phase rings (:mod:`stillframe.app.bench.phases`; ``--dds-observer``: by an
   observer node in this process, :mod:`stillframe.app.bench.latency`), beside sim_node's overruns,
   with a histogram, the worst ten samples explained phase by phase, and each step of a sample.
2. Lock-step: the full LQG scene through the three nodes, steps per second and the ratio of
   simulated to wall time, against the same scene in one process (``closed-loop``, the best of
   :data:`ONE_PROCESS_RUNS` in this run: the baseline is the loop's cost, not the machine's
   noise); each hop of a sample against a raw Cyclone ping-pong measured in the same run, and
   the phase timing's own cost (runs without it beside runs with it).

Both run once per middleware backend (``dds``: Cyclone; ``rclpy``: real rclpy on Fast DDS), all
three nodes on it, so the backends are compared in the same run. ``--compose`` /
``--compose-all`` run the real-time runs with those nodes in one process and add a composed
lock-step run; ``--record`` / ``--track`` repeat each real-time run with the recorder / the
modal tracker beside the loop, the figures without and with in one table (``--repeat N``: N such
pairs); each real-time run starts on a settled machine (:mod:`stillframe.app.bench.settle`: the last
run's children reaped, its pages flushed, an idle check printed), and its table says how much CPU
other jobs took during it; ``--rt`` runs the nodes with the real-time practices of
docs/realtime.md. The figures are printed beside the loop's goals (:data:`GOALS`), with the
machine's load average during each real-time run (the machine may be shared); ``--stall-probe``
runs cyclictest beside each real-time run (:mod:`stillframe.app.bench.stall_probe`) and prints the
machine's own stalls, which no practice of the loop can remove.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import shutil
import struct
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.arguments import add_json_argument, emit_json, seconds
from stillframe.app.bench import phases, pingpong
from stillframe.app.bench.busy import busy_loops
from stillframe.app.bench.latency import LatencyLog
from stillframe.app.bench.recorder_load import (
    RecorderRun,
    completeness,
    recorder_process,
    write_limit,
)
from stillframe.app.bench.settle import CpuShare, children_cpu_s, settle
from stillframe.app.bench.stall_probe import stall_probe
from stillframe.app.launch_cli import (
    add_compose_arguments,
    add_realtime_arguments,
    add_recorder_arguments,
    realtime_arguments,
    recorder_args,
)
from stillframe.app.launcher import run_scene
from stillframe.app.run_verdict import watchdog_zeros
from stillframe.config.scene import load_scene
from stillframe.contract.topics import DEFAULT_NAMESPACE, FLOOR_IMU, FORCE_CMD, TORQUE_CMD
from stillframe.errors import InputError
from stillframe.locations import SCENES_DIR
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.middleware import api
from stillframe.node_runtime.realtime import Realtime, RealtimeOptions, parse_practices
from stillframe.text_table import format_table

SCENE = SCENES_DIR / "thesis_lqg.yaml"
RATES_HZ: tuple[float, ...] = (100.0, 1000.0)
#: one-process runs of the scene; the fastest is the baseline
ONE_PROCESS_RUNS = 3
#: seconds of raw Cyclone ping-pong, back to back, for the floor of a lock-step hop
FLOOR_S = 3.0


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench loop``, its arguments and :func:`run` as its action to ``benches``."""
    parser = benches.add_parser("loop", help="closed-loop latency (real time) and lock-step speed",
                                description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--duration", type=seconds, default=10.0, metavar="S",
                        help="seconds of each real-time run (default 10)")
    parser.add_argument("--rate", dest="rates", action="append", type=float, default=[],
                        metavar="HZ", help="real-time rate (repeatable; default 100 and 1000)")
    parser.add_argument("--no-lockstep", dest="lockstep", action="store_false",
                        help="skip the lock-step runs")
    parser.add_argument("--backend", dest="backends", action="append", default=[],
                        choices=api.BACKENDS,
                        help="measure this backend (repeatable; default: every one installed)")
    parser.add_argument("--record", action="store_true",
                        help="run each real-time run twice, without and with `stillframe record "
                             "--all` beside it: the recorder's CPU time per message, its "
                             "messages/s, whether the bag is complete, its write path against "
                             "a bare mcap writer")
    add_recorder_arguments(parser)
    parser.add_argument("--repeat", type=int, default=1, metavar="N",
                        help="run each real-time run (and its recorded / tracked twin) N times, "
                             "the twins one after the other (default 1)")
    parser.add_argument("--track", action="store_true",
                        help="run each real-time run twice, without and with the modal tracker "
                             "(`launch --track`) beside it: deadline misses and p50/p99 of each")
    parser.add_argument("--load", type=int, default=0, metavar="N",
                        help="run each real-time run twice, without and with N busy loops "
                             "(`sh -c 'while :; do :; done'`, each in its own session) beside "
                             "it: the loop's figures on a busy workstation against its quiet "
                             "twin, in the same run")
    parser.add_argument("--dds-observer", action="store_true",
                        help="time each sample's latency by an observer node in this process "
                             "(DDS source timestamps of the floor-1 IMU and the command), as a "
                             "cross-check; by default the nodes' own phase rings time it, and no "
                             "observer takes messages, CPU or wake-ups from the loop")
    parser.add_argument("--stall-probe", action="store_true",
                        help="run cyclictest (rt-tests, root) beside each real-time run: "
                             "the machine's stalls of 1 ms or more, and its worst")
    add_compose_arguments(parser)
    add_realtime_arguments(parser, launch=False)
    add_json_argument(parser)
    parser.set_defaults(func=run)


def realtime_overrides(rate_hz: float, duration: float) -> list[str]:
    """The LQG scene at ``rate_hz`` for ``duration`` s: one midpoint step per sample at 1 kHz,
    ten at 100 Hz; control from half-time, evaluation windows of half the run."""
    steps = max(1, round(10_000.0 / rate_hz) // 10)
    return [f"sensors.rate_hz={rate_hz:g}", f"integrator.dt={1.0 / (rate_hz * steps)!r}",
            f"duration={duration:g}", f"controller.start={duration / 2:g}",
            f"evaluation.window={duration / 2:g}"]


_STAMP = struct.Struct("<iI")   # header.stamp, first in every stamped message's CDR


def stamp_ns(cdr: bytes) -> int:
    """The header stamp of a stamped message's CDR, in ns."""
    sec, nanosec = _STAMP.unpack_from(cdr, 4)
    return sec * 1_000_000_000 + nanosec


def observe(log: LatencyLog) -> Any:
    """A ``prepare`` hook for :func:`stillframe.app.launcher.run_scene`: the launcher's node logs
    floor-1 samples and both command topics with their source timestamps
    (:mod:`stillframe.app.bench.latency`), reading only the stamps from the raw bytes (the observer
    must keep up with 1 kHz on a loaded machine)."""

    def prepare(node: Any) -> None:
        def topic(spec: Any) -> str:
            return f"{DEFAULT_NAMESPACE}/{spec.name}"

        def sample(cdr: bytes, info: Any) -> None:
            log.on_sample(stamp_ns(cdr), info.source_timestamp)

        def command(cdr: bytes, info: Any) -> None:
            log.on_command(stamp_ns(cdr), info.source_timestamp)

        node.create_subscription(FLOOR_IMU[0].type_name, topic(FLOOR_IMU[0]), sample,
                                 FLOOR_IMU[0].qos, raw=True)
        for spec in (TORQUE_CMD, FORCE_CMD):
            node.create_subscription(spec.type_name, topic(spec), command, spec.qos, raw=True)

    return prepare


@contextlib.contextmanager
def observer_backend(backend: str) -> Iterator[None]:
    """The launcher's node (the observer) on the backend it measures, not the default one: an
    rclpy observer of a Cyclone loop pays rclpy's executor per message and falls behind at
    1 kHz, which it would count as the loop's latency."""
    before = os.environ.get(api.BACKEND_ENV)
    os.environ[api.BACKEND_ENV] = backend
    try:
        yield
    finally:
        if before is None:
            del os.environ[api.BACKEND_ENV]
        else:
            os.environ[api.BACKEND_ENV] = before


@contextlib.contextmanager
def observer_realtime(practices: str) -> Iterator[None]:
    """With ``fifo`` among the nodes' practices, the observer (this process) runs SCHED_FIFO too,
    one priority below the nodes, for the run: else the nodes starve it on a loaded machine and
    it measures its own delay. SCHED_OTHER again afterwards."""
    if "fifo" not in parse_practices(practices):
        yield
        return
    rt = Realtime(RealtimeOptions(frozenset({"fifo"}), RealtimeOptions().priority - 1))
    rt.enter()
    for text in rt.refused:
        print(f"bench loop: observer: {text}", file=sys.stderr)
    try:
        yield
    finally:
        rt.leave()


def realtime(rate_hz: float, duration: float, out: Path, backend: str, *,
             rt: tuple[str, list[int]] = ("", []),
             monitor_args: list[str] | None = None, compose: str = "",
             probe: bool = False, record: Sequence[str] | None = None,
             track: bool = False, dds_observer: bool = False, load: int = 0) -> dict[str, Any]:
    """The LQG scene in real time at ``rate_hz`` through the nodes on ``backend`` (composed as
    ``compose`` says): latency and deadline figures from the nodes' phase rings
    (:func:`stillframe.app.bench.phases.latency_log`), or with ``dds_observer`` as an observer here
    sees them; ``monitor_args`` start a monitor beside them; ``probe``: cyclictest beside them;
    ``record``: ``stillframe record --all`` beside them with these further arguments
    (:mod:`stillframe.app.bench.recorder_load`; None: no recorder);
    ``track``: the modal tracker beside them (:mod:`stillframe.app.tracking`); ``load``: that
    many busy loops beside them (:mod:`stillframe.app.bench.busy`)."""
    log = LatencyLog(round(1e9 / rate_hz))
    others = CpuShare()
    children_before = children_cpu_s()
    with (observer_backend(backend),
          observer_realtime(rt[0]) if dds_observer else contextlib.nullcontext(),
          stall_probe() if probe else contextlib.nullcontext() as stalls,
          busy_loops(load),
          recorder_process(out / "bag", backend, record) if record is not None
          else contextlib.nullcontext() as recorder):
        result = run_scene(SCENE, realtime_overrides(rate_hz, duration), out=out, mode="realtime",
                           prepare=observe(log) if dds_observer else None, backends=[backend],
                           rt=rt[0], rt_cpus=rt[1],
                           monitor_args=monitor_args, compose=compose, track=track,
                           phase_log=out / "phases")
    share = others.stop()      # the children are reaped here, the recorder too
    nodes_cpu_s = children_cpu_s() - children_before - (recorder.total_cpu_s if recorder else 0)
    e = result.evaluation
    recorded = recorder_figures(recorder, e["steps"], rate_hz) if recorder else {}
    if recorder:
        shutil.rmtree(recorder.bag, ignore_errors=True)   # read; its pages leave the cache
    rings = phases.load(out / "phases") if (out / "phases").is_dir() else {}
    if not dds_observer:
        log = phases.latency_log(rings, log.period_ns)
    summary = log.summary()
    zeros = watchdog_zeros(result.diagnostics)
    explained = explain_latency(log, out / "phases")
    return {"backend": backend, "compose": compose, "rate_hz": rate_hz, "rt": rt[0],
            "latency_from": "dds observer" if dds_observer else "phase rings",
            "rt_cpus": rt[1], **summary, "watchdog_zeros": zeros,
            "within_period_pct": within_period_pct(summary, zeros or 0),
            "sim_overruns": e.get("overruns"), "sim_deadline_misses": e.get("deadline_misses"),
            "steps": e["steps"], "degraded_samples": e.get("degraded_samples"),
            "load_1min": os.getloadavg()[0], **share, "nodes_cpu_s": nodes_cpu_s,
            "record": record is not None, "recorder_args": " ".join(record or []), **recorded,
            "track": track, "tracker_updates": len(result.tracked_modes), "busy_loops": load,
            **(stalls.summary if stalls else {}), **explained}


def explain_latency(log: LatencyLog, directory: Path) -> dict[str, Any]:
    """The latency histogram of the samples the observer saw answered, the worst ten explained
    by the nodes' phase rings in ``directory`` (when they wrote them), and each step's figures
    along the path."""
    latency = log.latencies_us()
    figures = path_figures(directory)
    paths = (phases.SamplePaths(phases.load(directory)) if figures else None)
    return {"histogram": phases.histogram(np.array(list(latency.values()))),
            "worst": phases.worst(latency, paths), **figures}


def recorder_figures(recorder: RecorderRun, steps: int, rate_hz: float) -> dict[str, Any]:
    """The recorder's CPU time per message (from its ready line to its exit, discovery and
    closing the bag included), the messages it wrote per second of the run, the per-step topics
    it holds against ``steps``, and its write path against a bare mcap writer."""
    counts = completeness(recorder.bag, steps, rate_hz)
    n = counts["bag_messages"]
    return {**counts, "recorder_cpu_s": recorder.cpu_s,
            "recorder_cpu_us_per_msg": 1e6 * recorder.cpu_s / n if n else float("nan"),
            "recorder_msgs_per_s": n * rate_hz / steps if steps else float("nan"),
            **write_limit(recorder.bag)}


def within_period_pct(summary: dict[str, Any], zeros: int) -> float:
    """The share of the samples seen that the control law answered within the period: the
    answered ones less the late ones and less the watchdog's ``zeros``. A zero goes out at the
    newest sample's stamp when the estimates fell ``watchdog_periods`` behind, so it is the first
    command of its stamp that the observer sees, and in time, though the law never answered that
    sample."""
    seen = summary["answered"] + summary["unanswered"]
    within = summary["answered"] - summary["deadline_misses"] - zeros
    return 100.0 * max(within, 0) / seen if seen else float("nan")


#: the loop's goals (docs/realtime.md): (figure, key, rate or None, test, goal text)
GOALS: tuple[tuple[str, str, float | None, Any, str], ...] = (
    ("answered within the period [%]", "within_period_pct", 1000.0, lambda v: v >= 99.9,
     ">= 99.9"),
    ("latency p99 [us]", "p99_us", 1000.0, lambda v: v <= 500.0, "<= 500"),
    ("latency max [us]", "max_us", 1000.0, lambda v: v <= 2000.0, "<= 2000"),
    ("latency p99 [us]", "p99_us", 100.0, lambda v: v <= 500.0, "<= 500"),
    ("lock-step through the nodes [steps/s]", "nodes_steps_per_s", None,
     lambda v: v >= 2500.0, ">= 2500"),
    ("one process [steps/s]", "one_process_steps_per_s", None, lambda v: v >= 20000.0,
     ">= 20000"),
    ("composed / one process", "composed_over_one_process", None, lambda v: v >= 0.7,
     ">= 0.7"),
)


def goal_rows(rows: list[dict[str, Any]], speeds: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each measured figure with its goal (:data:`GOALS`) and whether it is met."""
    out = []
    for figure, key, rate, test, goal in GOALS:
        runs = [r for r in (speeds if rate is None else
                            [r for r in rows if r["rate_hz"] == rate]) if key in r]
        if key.startswith("one_process"):
            runs = runs[:1]     # measured once, without DDS
        for r in runs:
            label = f"{figure}, {r['rate_hz']:g} Hz" if rate is not None else figure
            backend = "-" if key.startswith("one_process") else r["backend"]
            out.append({"figure": label, "backend": backend, "value": r[key],
                        "goal": goal, "met": bool(test(r[key]))})
    return out


def lockstep(out: Path, backend: str, one: dict[str, Any], compose: str,
             rt: tuple[str, list[int]] = ("", []), pairs: int = 1) -> dict[str, Any]:
    """The full LQG scene through the nodes on ``backend`` (with the real-time practices ``rt``)
    against ``one`` (one process); with ``compose`` ("pair", "all") also with those nodes
    composed in one process. ``pairs`` times a run without the phase timing, then one with it:
    the timing's cost as the ratio of their walls, and the last timed run's path per hop."""
    scene = load_scene(SCENE)
    walls: dict[bool, list[float]] = {False: [], True: []}
    for pair in range(pairs):
        for timed in (False, True):
            where = out / f"{'timed' if timed else 'untimed'}-{pair}"
            started = time.perf_counter()
            nodes = run_scene(SCENE, out=where, mode="lockstep", backends=[backend], rt=rt[0],
                              rt_cpus=rt[1], phase_timing=timed,
                              phase_log=where / "phases" if timed else None).evaluation
            launch_wall = time.perf_counter() - started
            walls[timed].append(nodes["wall_s"])
    hops = path_figures(where / "phases")
    composed = {}
    if compose:
        c = run_scene(SCENE, out=out / "composed", mode="lockstep", backends=[backend],
                      compose=compose, rt=rt[0], rt_cpus=rt[1]).evaluation
        composed = {"compose": compose, "composed_steps_per_s": c["steps"] / c["wall_s"],
                    "composed_over_one_process": one["loop_s"] / c["wall_s"],
                    "composed_over_nodes": nodes["wall_s"] / c["wall_s"]}
    return {**composed,
        "backend": backend, "rt": rt[0], "scene": scene.name, "steps": nodes["steps"],
        "sim_s": scene.duration,
        "nodes_wall_s": nodes["wall_s"], "launch_wall_s": launch_wall,
        "nodes_steps_per_s": nodes["steps"] / nodes["wall_s"],
        "nodes_realtime_ratio": scene.duration / nodes["wall_s"],
        "one_process_wall_s": one["loop_s"],
        "one_process_steps_per_s": one["steps"] / one["loop_s"],
        "nodes_over_one_process": one["loop_s"] / nodes["wall_s"],
        "complete": nodes.get("complete"),
        "reduction_pct": nodes["reduction_pct"],
        "untimed_wall_s": walls[False], "timed_wall_s": walls[True],
        "timing_cost_ratio": float(np.median(np.array(walls[True]) / np.array(walls[False]))),
        **hops,
    }


def path_figures(directory: Path) -> dict[str, Any]:
    """The phase rings the nodes wrote to ``directory`` as each step's figures along a sample's
    path and beside it (:mod:`stillframe.app.bench.phases`); empty when sim_node's is missing."""
    rings = phases.load(directory) if directory.is_dir() else {}
    if phases.SIM not in rings:
        return {}
    paths = phases.SamplePaths(rings)
    return {"path": paths.table(phases.PATH), "beside": paths.table(phases.BESIDE),
            "rt_budget": phases.rt_budget(rings),
            "rt_applied": {node: ring.meta.get("rt_applied", []) for node, ring in rings.items()},
            "rt_refused": {node: ring.meta.get("rt_refused", []) for node, ring in rings.items()}}


def twin(rows: list[dict[str, Any]], r: dict[str, Any]) -> dict[str, Any] | None:
    """The run without recorder or tracker of the same backend, rate and repeat as ``r``."""
    return next((b for b in rows if not b["record"] and not b["track"]
                 and not b.get("busy_loops")
                 and (b["backend"], b["rate_hz"], b.get("repeat", 0))
                 == (r["backend"], r["rate_hz"], r.get("repeat", 0))), None)


#: a recorded run may miss at most this many times the deadlines of its unrecorded twin (a
#: recorder beside the loop must cost it nothing it would notice: docs/realtime.md)
RECORDED_MISS_RATIO = 2.0


def recorder_verdict(r: dict[str, Any], base: dict[str, Any] | None) -> tuple[float, bool]:
    """A recorded run against its unrecorded twin: the ratio of sim_node's deadline
    misses, and whether the run holds: at most :data:`RECORDED_MISS_RATIO` times the misses,
    no degraded samples, every per-step sample in the bag and no hole (a twin without misses
    allows two: one miss more or less is not a ratio)."""
    if base is None:
        return math.nan, False
    misses, before = r["sim_deadline_misses"] or 0, base["sim_deadline_misses"] or 0
    ratio = misses / before if before else (math.inf if misses else 1.0)
    holds = (misses <= RECORDED_MISS_RATIO * max(before, 1) and not r["degraded_samples"]
             and r["complete"] and r["per_step_holes"] == 0)
    return ratio, holds


def recorder_table(rows: list[dict[str, Any]]) -> str:
    """Each real-time run without and with the recorder: the loop's figures, the recorder's
    cost and throughput, whether the bag holds every per-step sample, and whether the recorded
    run holds :data:`RECORDED_MISS_RATIO` against its twin (:func:`recorder_verdict`)."""
    def recorded(r: dict[str, Any], key: str, form: str) -> str:
        return format(r[key], form) if r["record"] else "-"

    def verdict(r: dict[str, Any]) -> list[str]:
        if not r["record"]:
            return ["-", "-"]
        ratio, holds = recorder_verdict(r, twin(rows, r))
        return [f"{ratio:.2f}", "yes" if holds else "NO"]

    return format_table(
        ["backend", "rate [Hz]", "recorder", "sim deadline misses", "degraded", "p50 [us]",
         "p99 [us]", "recorder CPU [us/msg]", "recorded [msg/s]", "per-step in bag / steps",
         "holes", "write path [msg/CPU s]", "bare mcap [msg/CPU s]", "nodes' CPU [s]",
         "misses / unrecorded", "holds"],
        [[r["backend"], f"{r['rate_hz']:g}",
          (r.get("recorder_args") or "yes") if r["record"] else "no",
          r["sim_deadline_misses"], "-" if r["degraded_samples"] is None else r["degraded_samples"],
          f"{r['p50_us']:.0f}", f"{r['p99_us']:.0f}",
          recorded(r, "recorder_cpu_us_per_msg", ".1f"), recorded(r, "recorder_msgs_per_s", ".0f"),
          f"{r['per_step_min']} / {r['steps']}" if r["record"] else "-",
          r["per_step_holes"] if r["record"] else "-",
          recorded(r, "write_path_msgs_per_s", ".0f"), recorded(r, "mcap_msgs_per_s", ".0f"),
          f"{r['nodes_cpu_s']:.1f}", *verdict(r)]
         for r in rows])


def loaded_table(rows: list[dict[str, Any]]) -> str:
    """Each run beside the busy loops against its quiet twin: the share within the period, the
    latency p50 / p99 / max and sim_node's deadline misses of each, and the p99 ratio."""
    out = []
    for r in rows:
        base = twin(rows, r)
        if not r.get("busy_loops") or base is None:
            continue
        out.append([r["backend"], f"{r['rate_hz']:g}", r["rt"] or "-", r["busy_loops"],
                    *(f"{base[k]:.2f} / {r[k]:.2f}" for k in ("within_period_pct",)),
                    *(f"{base[k]:.0f} / {r[k]:.0f}" for k in ("p50_us", "p99_us", "max_us")),
                    f"{base['sim_deadline_misses']} / {r['sim_deadline_misses']}",
                    f"{r['p99_us'] / base['p99_us']:.2f}" if base["p99_us"] else "-"])
    return format_table(
        ["backend", "rate [Hz]", "--rt", "busy loops", "within period [%] (quiet / loaded)",
         "p50 [us]", "p99 [us]", "max [us]", "sim deadline misses", "p99 loaded / quiet"], out)


def tracker_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per backend and rate, the run with the modal tracker against the one without: deadline
    misses (the observer's and sim_node's) and latency p50 / p99 of each, and with / without."""
    out = []
    for r in rows:
        base = twin(rows, r)
        if not r["track"] or base is None:
            continue
        pair = {key: (base[key], r[key])
                for key in ("deadline_misses", "sim_deadline_misses", "p50_us", "p99_us")}
        out.append({"backend": r["backend"], "rate_hz": r["rate_hz"], **pair,
                    "p99_ratio": r["p99_us"] / base["p99_us"] if base["p99_us"] else float("nan"),
                    "tracker_updates": r["tracker_updates"]})
    return out


def tracker_table(pairs: list[dict[str, Any]]) -> str:
    """:func:`tracker_rows` as a table: each figure without / with the tracker."""
    def both(pair: tuple[Any, Any], form: str = "") -> str:
        return " / ".join("-" if v is None else format(v, form) for v in pair)

    return format_table(
        ["backend", "rate [Hz]", "deadline misses (without / with tracker)",
         "sim deadline misses", "p50 [us]", "p99 [us]", "p99 with / without",
         "tracker updates"],
        [[p["backend"], f"{p['rate_hz']:g}", both(p["deadline_misses"]),
          both(p["sim_deadline_misses"]), both(p["p50_us"], ".0f"), both(p["p99_us"], ".0f"),
          f"{p['p99_ratio']:.2f}", p["tracker_updates"]] for p in pairs])


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    if not args.duration >= 1.0:
        raise InputError("bench loop: --duration must be >= 1 s")
    backends = args.backends or [b for b in api.BACKENDS if b == "dds" or api.has_rclpy()]
    for backend in backends:
        api.check_backend(backend, f"bench loop --backend {backend}")
    practices, cpus = realtime_arguments(args)
    rt = (practices or "", cpus)     # the bench measures what it is given: no default
    rates = args.rates or list(RATES_HZ)
    if not all(1.0 <= r <= 10_000.0 for r in rates):
        raise InputError(f"bench loop: --rate must be 1..10000 Hz, got {rates}")
    if not 0 <= args.load <= 64:
        raise InputError(f"bench loop: --load must be 0..64 busy loops, got {args.load}")
    if not 1 <= args.repeat <= 100:
        raise InputError(f"bench loop: --repeat must be 1..100, got {args.repeat}")
    one = min((run_closed_loop(load_scene(SCENE)).evaluation for _ in range(ONE_PROCESS_RUNS)),
              key=lambda e: e["loop_s"]) if args.lockstep else {}
    rows, speeds, floor = [], [], {}
    with tempfile.TemporaryDirectory(prefix="stillframe-bench-loop-") as tmp:
        for backend in backends:
            for rate, repeat in ((rate, i) for rate in rates for i in range(args.repeat)):
                variants = [("", {})] + ([("recorded", {"record": recorder_args(args) or []})]
                                          if args.record
                                          else []) + ([("tracked", {"track": True})]
                                                      if args.track else []) + (
                    [(f"beside {args.load} busy loops", {"load": args.load})] if args.load
                    else [])
                for name, extra in variants:
                    settled = settle()
                    print(f"{backend}: real time at {rate:g} Hz for {args.duration:g} s"
                          + (f" (--rt {rt[0]})" if rt[0] else "")
                          + (f", {name}" if name else "")
                          + (f", run {repeat + 1} of {args.repeat}" if args.repeat > 1 else "")
                          + f"; {settled.text()}", file=sys.stderr)
                    rows.append({"repeat": repeat, **settled.figures(), **realtime(
                        rate, args.duration,
                        Path(tmp) / f"{backend}{rate:g}-{repeat}{'-' + name if name else ''}",
                        backend, rt=rt, compose=args.compose, probe=args.stall_probe,
                        dds_observer=args.dds_observer, **extra)})
            if args.lockstep:
                print(f"{backend}: lock-step, the full LQG scene", file=sys.stderr)
                speeds.append(lockstep(Path(tmp) / f"{backend}-lockstep", backend, one,
                                       args.compose, rt, pairs=args.repeat))
        if args.lockstep:
            print(f"raw Cyclone ping-pong, back to back, {FLOOR_S:g} s (the floor of a hop)",
                  file=sys.stderr)
            floor = pingpong.measure(0, FLOOR_S, ("raw",))["raw"]
    for r in rows:
        if r["record"]:
            ratio, r["holds_issue_32"] = recorder_verdict(r, twin(rows, r))
            r["misses_over_unrecorded"] = ratio if math.isfinite(ratio) else None
    goals = goal_rows(rows, speeds)
    if args.json:
        emit_json({"realtime": rows, "lockstep": speeds, "goals": goals,
                   "tracker": tracker_rows(rows), "cpus": os.cpu_count(), "floor": floor})
        return 0
    print(format_table(
        ["backend", "composed", "rate [Hz]", "busy loops", "samples", "answered",
         "within period [%]", "p50 [us]",
         "p99 [us]", "max [us]", "deadline misses", "watchdog zeros", "unanswered", "unobserved",
         "sim overruns",
         "machine stalls (worst [us])", "load", "others' CPUs (niced)"],
        [[r["backend"], r["compose"] or "-", f"{r['rate_hz']:g}", r["busy_loops"], r["samples"],
          r["answered"],
          f"{r['within_period_pct']:.2f}", f"{r['p50_us']:.0f}",
          f"{r['p99_us']:.0f}", f"{r['max_us']:.0f}", r["deadline_misses"],
          "-" if r["watchdog_zeros"] is None else r["watchdog_zeros"], r["unanswered"],
          r["unobserved"], r["sim_overruns"] if r["sim_overruns"] is not None else "-",
          f"{r['probe_stalls']} ({r['probe_max_us']})" if "probe_stalls" in r else "-",
          f"{r['load_1min']:.2f}",
          f"{r['others_cpus']:.2f} ({r['others_niced_cpus']:.2f})"] for r in rows]))
    if args.record:
        print(recorder_table([r for r in rows if not r["track"]]))
    if args.track:
        print(tracker_table(tracker_rows(rows)))
    if args.load:
        print(loaded_table(rows))
    for r in rows:
        print(explained_text(r))
    print(format_table(["figure", "backend", "measured", "goal", "met"],
                       [[g["figure"], g["backend"], f"{g['value']:.4g}", g["goal"],
                         "yes" if g["met"] else "NO"] for g in goals]))
    if not speeds:
        return 0
    print(format_table(
        ["lock-step", "steps", "wall [s]", "steps/s", "x real time", "/ one process",
         "complete"],
        [[s["backend"], s["steps"], f"{s['nodes_wall_s']:.2f}", f"{s['nodes_steps_per_s']:.0f}",
          f"{s['nodes_realtime_ratio']:.2f}", f"{s['nodes_over_one_process']:.2f}",
          s["complete"]] for s in speeds]
        + [[f"{s['backend']} composed ({s['compose']})", s["steps"], "",
            f"{s['composed_steps_per_s']:.0f}", "", f"{s['composed_over_one_process']:.2f}", ""]
           for s in speeds if args.compose]
        + [["one process", one["steps"], f"{one['loop_s']:.2f}",
            f"{one['steps'] / one['loop_s']:.0f}", "", "1.00", ""]]))
    for s in speeds:
        print(f"\n{s['backend']}: lock-step, one sample's path (the last timed run); phase timing "
              f"costs x{s['timing_cost_ratio']:.3f} of the wall of a run without it "
              f"(median of {len(s['timed_wall_s'])} pair(s), same run)")
        if "path" in s:
            print(phases.path_table(s["path"], s["beside"], floor.get("p50_us")))
    return 0


def explained_text(r: dict[str, Any]) -> str:
    """A real-time run's latency histogram and worst ten samples, explained."""
    head = (f"\n{r['backend']}{' composed ' + r['compose'] if r['compose'] else ''}, "
            f"{r['rate_hz']:g} Hz{' --rt ' + r['rt'] if r['rt'] else ''}")
    parts = [f"{head}: latency of the samples answered", phases.histogram_text(r["histogram"]),
             f"{head}: the worst ten samples", phases.worst_text(r["worst"])]
    if "path" in r:
        parts += [f"{head}: each step of a sample (nodes' practices: "
                  + "; ".join(f"{n} {', '.join(a) or 'none'}" for n, a in r["rt_applied"].items())
                  + ")", phases.path_table(r["path"], r["beside"]), r["rt_budget"]]
    return "\n".join(parts)
