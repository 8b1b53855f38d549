"""``stillframe bench loop``: the closed loop's latency in real time and its lock-step speed.

1. Real-time mode at 100 Hz and 1 kHz (the LQG scene with ``sensors.rate_hz`` and a matching
   ``integrator.dt``): sensor-stamp-to-command latency p50 / p99 / max and deadline misses, seen
   by an observer in this process (:mod:`stillframe.loop.latency`), beside sim_node's overruns.
2. Lock-step: the full LQG scene through the three nodes, steps per second and the ratio of
   simulated to wall time, against the same scene in one process (``closed-loop``) in this run.

Both run once per middleware backend (``dds``: Cyclone; ``rclpy``: real rclpy on Fast DDS), all
three nodes on it, so the backends are compared in the same run.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from stillframe.app.commands.common import add_json_argument, emit_json
from stillframe.app.launcher import run_scene
from stillframe.config.scene import load_scene
from stillframe.contract.topics import DEFAULT_NAMESPACE, FLOOR_IMU, FORCE_CMD, TORQUE_CMD
from stillframe.errors import InputError
from stillframe.locations import SCENES_DIR
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.loop.latency import LatencyLog
from stillframe.middleware import api
from stillframe.text_table import format_table

SCENE = SCENES_DIR / "thesis_lqg.yaml"
RATES_HZ: tuple[float, ...] = (100.0, 1000.0)


def register(benches: argparse._SubParsersAction) -> None:
    parser = benches.add_parser("loop", help="closed-loop latency (real time) and lock-step speed",
                                description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--duration", type=float, default=10.0, metavar="S",
                        help="seconds of each real-time run (default 10)")
    parser.add_argument("--backend", dest="backends", action="append", default=[],
                        choices=api.BACKENDS,
                        help="measure this backend (repeatable; default: every one installed)")
    parser.add_argument("--compose", action="store_true",
                        help="also lock-step with the estimator and controller in one process")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def realtime_overrides(rate_hz: float, duration: float) -> list[str]:
    """The LQG scene at ``rate_hz`` for ``duration`` s: one midpoint step per sample at 1 kHz,
    ten at 100 Hz; control from half-time, evaluation windows of half the run."""
    steps = max(1, round(10_000.0 / rate_hz) // 10)
    return [f"sensors.rate_hz={rate_hz:g}", f"integrator.dt={1.0 / (rate_hz * steps)!r}",
            f"duration={duration:g}", f"controller.start={duration / 2:g}",
            f"evaluation.window={duration / 2:g}"]


def stamp_ns(msg: Any) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def observe(log: LatencyLog) -> Any:
    """A ``prepare`` hook for :func:`stillframe.app.launcher.run_scene`: the launcher's node logs
    floor-1 samples and both command topics, on the wall clock."""

    def prepare(node: Any) -> None:
        def topic(spec: Any) -> str:
            return f"{DEFAULT_NAMESPACE}/{spec.name}"

        node.create_subscription(FLOOR_IMU[0].type_name, topic(FLOOR_IMU[0]),
                                 lambda m: log.on_sample(stamp_ns(m), time.time_ns()),
                                 FLOOR_IMU[0].qos)
        for spec in (TORQUE_CMD, FORCE_CMD):
            node.create_subscription(spec.type_name, topic(spec),
                                     lambda m: log.on_command(stamp_ns(m), time.time_ns()),
                                     spec.qos)

    return prepare


def realtime(rate_hz: float, duration: float, out: Path, backend: str) -> dict[str, Any]:
    log = LatencyLog(round(1e9 / rate_hz))
    result = run_scene(SCENE, realtime_overrides(rate_hz, duration), out, "realtime",
                       prepare=observe(log), backends=[backend])
    e = result.evaluation
    return {"backend": backend, "rate_hz": rate_hz, **log.summary(),
            "sim_overruns": e.get("overruns"), "steps": e["steps"]}


def lockstep(out: Path, backend: str, one: dict[str, Any], compose: bool) -> dict[str, Any]:
    """The full LQG scene through the nodes on ``backend`` against ``one`` (one process);
    with ``compose`` also with the estimator and controller composed in one process."""
    scene = load_scene(SCENE)
    started = time.perf_counter()
    nodes = run_scene(SCENE, [], out, "lockstep", backends=[backend]).evaluation
    launch_wall = time.perf_counter() - started
    composed = {}
    if compose:
        c = run_scene(SCENE, [], out / "composed", "lockstep", backends=[backend],
                      compose=True).evaluation
        composed = {"composed_steps_per_s": c["steps"] / c["wall_s"],
                    "composed_over_one_process": one["loop_s"] / c["wall_s"],
                    "composed_over_nodes": nodes["wall_s"] / c["wall_s"]}
    return {**composed,
        "backend": backend, "scene": scene.name, "steps": nodes["steps"], "sim_s": scene.duration,
        "nodes_wall_s": nodes["wall_s"], "launch_wall_s": launch_wall,
        "nodes_steps_per_s": nodes["steps"] / nodes["wall_s"],
        "nodes_realtime_ratio": scene.duration / nodes["wall_s"],
        "one_process_wall_s": one["loop_s"],
        "one_process_steps_per_s": one["steps"] / one["loop_s"],
        "nodes_over_one_process": one["loop_s"] / nodes["wall_s"],
        "lockstep_timeouts": nodes.get("lockstep_timeouts"),
        "reduction_pct": nodes["reduction_pct"],
    }


def run(args: argparse.Namespace) -> int:
    if not args.duration >= 1.0:
        raise InputError("bench loop: --duration must be >= 1 s")
    backends = args.backends or [b for b in api.BACKENDS if b == "dds" or api.has_rclpy()]
    for backend in backends:
        api.check_backend(backend, f"bench loop --backend {backend}")
    one = run_closed_loop(load_scene(SCENE)).evaluation
    rows, speeds = [], []
    with tempfile.TemporaryDirectory(prefix="stillframe-bench-loop-") as tmp:
        for backend in backends:
            for rate in RATES_HZ:
                print(f"{backend}: real time at {rate:g} Hz for {args.duration:g} s",
                      file=sys.stderr)
                rows.append(realtime(rate, args.duration, Path(tmp) / f"{backend}{rate:g}",
                                     backend))
            print(f"{backend}: lock-step, the full LQG scene", file=sys.stderr)
            speeds.append(lockstep(Path(tmp) / f"{backend}-lockstep", backend, one,
                                   args.compose))
    if args.json:
        emit_json({"realtime": rows, "lockstep": speeds})
        return 0
    print(format_table(
        ["backend", "rate [Hz]", "samples", "answered", "p50 [us]", "p99 [us]", "max [us]",
         "deadline misses", "unanswered", "sim overruns"],
        [[r["backend"], f"{r['rate_hz']:g}", r["samples"], r["answered"], f"{r['p50_us']:.0f}",
          f"{r['p99_us']:.0f}", f"{r['max_us']:.0f}", r["deadline_misses"], r["unanswered"],
          r["sim_overruns"] if r["sim_overruns"] is not None else "-"] for r in rows]))
    print(format_table(
        ["lock-step", "steps", "wall [s]", "steps/s", "x real time", "/ one process",
         "timeouts"],
        [[s["backend"], s["steps"], f"{s['nodes_wall_s']:.2f}", f"{s['nodes_steps_per_s']:.0f}",
          f"{s['nodes_realtime_ratio']:.2f}", f"{s['nodes_over_one_process']:.2f}",
          s["lockstep_timeouts"]] for s in speeds]
        + [[f"{s['backend']} composed", s["steps"], "", f"{s['composed_steps_per_s']:.0f}", "",
            f"{s['composed_over_one_process']:.2f}", ""] for s in speeds if args.compose]
        + [["one process", one["steps"], f"{one['loop_s']:.2f}",
            f"{one['steps'] / one['loop_s']:.0f}", "", "1.00", ""]]))
    return 0
