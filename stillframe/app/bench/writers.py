"""``stillframe bench writers``: a real-time loop beside a foreign writer, against its twin.

Per backend, ``--repeats`` pairs of real-time launches of the thesis LQG scene (``--rate``, default
the scene's 32 Hz; ``--duration`` s, control from half-time), the two of a pair one after the
other, their order alternating: one alone, one beside ``stillframe topic pub --rate
WRITER_RATE`` of a plausible torque on ``/frame/pendulum/torque_cmd`` (what ``ros2 topic pub -r
50`` does), started before the launch and on the same backend. Printed per run: sim_node's
deadline misses and overruns, the commands it refused for their writer (the foreign writer's,
and the loop's own controller's, which must be none), the writers named, the reductions; then
the misses beside the writer against the twins' (the goal: within 2x).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from stillframe.app.arguments import add_json_argument, emit_json, seconds
from stillframe.errors import InputError
from stillframe.text_table import format_table

#: the foreign writer: ``ros2 topic pub -r 50 /frame/pendulum/torque_cmd`` of 0.5 N m
TOPIC = "/frame/pendulum/torque_cmd"
MESSAGE = "{header: auto, wrench: {torque: {z: 0.5}}}"
#: how many times the twin's misses the run beside the writer may have (a foreign writer must
#: not cost the loop its deadlines: docs/nodes.md, writer identity)
GOAL_RATIO = 2.0


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench writers``, its arguments and :func:`run` as its action to
    ``benches``."""
    parser = benches.add_parser("writers", help="a real-time loop beside a foreign writer on its "
                                                "command topic, against its twin without it",
                                description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--duration", type=seconds, default=20.0, metavar="S",
                        help="simulated (= wall) seconds of each run (default 20)")
    parser.add_argument("--rate", type=float, default=None, metavar="HZ",
                        help="the loop's sample rate (default: the scene's, 32 Hz)")
    parser.add_argument("--writer-rate", type=float, default=50.0, metavar="HZ",
                        help="the foreign writer's rate (default 50)")
    parser.add_argument("--repeats", type=int, default=2, metavar="N",
                        help="pairs of runs per backend (default 2)")
    parser.add_argument("--backend", dest="backends", action="append", default=[],
                        metavar="BACKEND", help="dds or rclpy (repeatable; default: every "
                        "installed one)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def start_writer(backend: str, rate: float) -> subprocess.Popen:
    """``stillframe topic pub`` on ``backend``, writing until SIGINT."""
    return subprocess.Popen(
        [sys.executable, "-m", "stillframe", "topic", "pub", TOPIC,
         "geometry_msgs/msg/WrenchStamped", MESSAGE, "--rate", f"{rate:g}"],
        env=dict(os.environ, STILLFRAME_RMW=backend), stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)


def stop(proc: subprocess.Popen) -> None:
    """Stop ``proc`` as Ctrl-C would; kill it if it has not ended 10 s later."""
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def one_run(backend: str, overrides: list[str], out: Path, writer_rate: float | None,
            ) -> dict[str, Any]:
    """One real-time launch, beside a writer at ``writer_rate`` (None: alone)."""
    from stillframe.app.launcher import run_scene
    from stillframe.app.run_verdict import foreign_writers, writer_refusals
    from stillframe.locations import SCENES_DIR

    writer = None if writer_rate is None else start_writer(backend, writer_rate)
    try:
        result = run_scene(SCENES_DIR / "thesis_lqg.yaml", overrides, out=out, mode="realtime",
                           backends=[backend])
    finally:
        if writer is not None:
            stop(writer)
    ev = result.evaluation
    gate = ev["command_gates"]["pendulum/torque_cmd"]
    foreign = foreign_writers(ev, result.diagnostics)
    return {"backend": backend, "writer": writer_rate is not None, "steps": ev["steps"],
            "deadline_misses": ev["deadline_misses"], "overruns": ev["overruns"],
            "refused_foreign": int(gate["rejected_foreign_writer"]),
            "refused_own_for_writer": writer_refusals(ev) - int(gate["rejected_foreign_writer"]),
            "named": sorted({w for f in foreign for w in f["writers"]}),
            "reduction_pct": ev["reduction_pct"]["displacement"]}


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per backend: the misses beside the writer and without it (summed over the repeats), their
    ratio (None when the twins missed none) and whether it is within :data:`GOAL_RATIO` (of one
    miss at least: twins without any allow two)."""
    out = []
    for backend in dict.fromkeys(r["backend"] for r in rows):
        beside = sum(r["deadline_misses"] for r in rows if r["backend"] == backend and r["writer"])
        alone = sum(r["deadline_misses"] for r in rows
                    if r["backend"] == backend and not r["writer"])
        out.append({"backend": backend, "misses_beside": beside, "misses_alone": alone,
                    "ratio": beside / alone if alone else None,
                    "within_goal": beside <= GOAL_RATIO * max(alone, 1)})
    return out


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    from stillframe.app.bench.loop import realtime_overrides
    from stillframe.middleware import api

    if not args.duration >= 4.0:
        raise InputError("bench writers: --duration must be >= 4 s")
    if args.repeats < 1 or not args.writer_rate > 0:
        raise InputError("bench writers: --repeats must be >= 1 and --writer-rate > 0")
    backends = args.backends or [b for b in api.BACKENDS if b == "dds" or api.has_rclpy()]
    for backend in backends:
        api.check_backend(backend, f"--backend {backend}")
    if args.rate is None:
        d = args.duration
        overrides = [f"duration={d:g}", f"controller.start={d / 2:g}",
                     f"evaluation.window={d / 2:g}"]
    else:
        overrides = realtime_overrides(args.rate, args.duration)
    rows = []
    with tempfile.TemporaryDirectory(prefix="stillframe-bench-writers-") as tmp:
        for backend in backends:
            for i in range(args.repeats):
                for beside in ((False, True) if i % 2 == 0 else (True, False)):
                    print(f"bench writers: {backend}, run {i + 1}, "
                          f"{'beside the writer' if beside else 'alone'}", file=sys.stderr)
                    rows.append(one_run(backend, overrides, Path(tmp) / str(len(rows)),
                                        args.writer_rate if beside else None))
    totals = summary(rows)
    if args.json:
        emit_json({"duration_s": args.duration, "writer_rate_hz": args.writer_rate,
                   "overrides": overrides, "rows": rows, "summary": totals})
        return 0
    print(format_table(
        ["backend", "writer", "steps", "deadline misses", "overruns", "refused (writer's)",
         "refused (own, for writer)", "named", "x red. % (1 2 3)"],
        [[r["backend"], "beside" if r["writer"] else "alone", r["steps"], r["deadline_misses"],
          r["overruns"], r["refused_foreign"], r["refused_own_for_writer"],
          ", ".join(r["named"]) or "-", " ".join(f"{v:.1f}" for v in r["reduction_pct"])]
         for r in rows]))
    for t in totals:
        ratio = "" if t["ratio"] is None else f": x{t['ratio']:.2f}"
        print(f"{t['backend']}: {t['misses_beside']} deadline misses beside the writer, "
              f"{t['misses_alone']} alone{ratio} "
              f"({'within' if t['within_goal'] else 'NOT within'} {GOAL_RATIO:g}x)")
    return 0
