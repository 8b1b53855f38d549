"""``stillframe bench soak``: one hour of simulated lock-step LQG through the three node
processes (115,200 samples at 32 Hz), each process's resident set size sampled against sim time.

Reported per process: RSS after warm-up, at the end (the last second of sim time left out: the
simulator then evaluates the run and writes its results), and the growth between (must stay
below 5 %; the simulator's net of the histories it keeps by design,
:mod:`stillframe.app.bench.rss`), and the loop's counters at the end (whether it completed,
safe-state samples, rejected commands, malformed samples; the nodes' last ``/diagnostics``).
Progress (sim time, RSS) goes to stderr.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from stillframe.app.arguments import add_json_argument, emit_json, seconds
from stillframe.app.bench.rss import RssLog, rss_bytes
from stillframe.app.launcher import Launcher, LaunchOptions
from stillframe.config.scene import load_scene, sample_grid
from stillframe.contract import messages, topics
from stillframe.errors import InputError
from stillframe.locations import SCENES_DIR
from stillframe.text_table import format_table

SCENE = SCENES_DIR / "thesis_lqg.yaml"
GROWTH_LIMIT_PCT = 5.0
COUNTERS = ("complete", "safe_state_samples", "rejected_commands", "malformed_samples")


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench soak``, its arguments and :func:`run` as its action to ``benches``."""
    parser = benches.add_parser("soak", help="one hour of lock-step LQG: memory and counters",
                                description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--duration", type=seconds, default=3600.0, metavar="S",
                        help="simulated seconds (default 3600: 115,200 samples)")
    parser.add_argument("--warmup", type=float, default=0.1, metavar="FRACTION",
                        help="part of the run before the growth is measured (default 0.1)")
    parser.add_argument("--every", type=float, default=2.0, metavar="S",
                        help="wall seconds between RSS samples (default 2)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def overrides(duration: float) -> list[str]:
    """The LQG scene for ``duration`` s, control from 10 s, evaluation windows of 10 s."""
    return [f"duration={duration:g}", "controller.start=10", "evaluation.window=10"]


def soak(duration: float, warmup: float, every: float, out: Path) -> dict[str, Any]:
    """Run the soak; RSS growth per process and the counters."""
    scene = load_scene(SCENE, overrides(duration))
    period, substeps = sample_grid(scene)
    launcher = Launcher(LaunchOptions(SCENE, overrides(duration), mode="lockstep",
                                      result_file=out / "result.json"))
    clock = [0.0]
    launcher.node.create_subscription(
        topics.CLOCK.type_name, topics.CLOCK.name,
        lambda m: clock.__setitem__(0, messages.stamp_ns(m.clock) * 1e-9), topics.CLOCK.qos)
    log, done = RssLog(), threading.Event()

    def sample() -> None:
        while not done.wait(every):
            for child in launcher.processes.children:
                if (rss := rss_bytes(child.pid)) is not None:
                    log.add(child.name, clock[0], rss)
            print(f"soak: sim {clock[0]:.0f} / {duration:g} s  " + "  ".join(
                f"{name} {s[-1][1] / 2**20:.1f} MiB" for name, s in log.samples.items()),
                file=sys.stderr, flush=True)

    sampler = threading.Thread(target=sample, daemon=True)
    started = time.perf_counter()
    sampler.start()
    try:
        result = launcher.run()
    finally:
        done.set()
        sampler.join()
    e = result.evaluation
    # up to the last second of sim time: then the sim also evaluates and writes its results
    growth = {name: log.growth(name, warmup * duration,
                               (period, substeps) if name == "sim_node" else None,
                               until_s=duration - 1.0)
              for name in log.samples}
    return {"sim_s": duration, "steps": e["steps"], "wall_s": time.perf_counter() - started,
            "warmup_sim_s": warmup * duration, "growth_limit_pct": GROWTH_LIMIT_PCT,
            "rss": growth, "counters": {k: e.get(k) for k in COUNTERS},
            "command_gates": e.get("command_gates"), "reduction_pct": e.get("reduction_pct"),
            "diagnostics": result.diagnostics,
            "rss_samples": {name: s for name, s in log.samples.items()}}


def within_limit(report: dict[str, Any]) -> bool:
    """Every process's growth after warm-up (the simulator's net of its histories) < 5 %."""
    return all(g and g.get("net_growth_pct", g["growth_pct"]) < GROWTH_LIMIT_PCT
               for g in report["rss"].values())


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    if not args.duration >= 20.0:
        raise InputError("bench soak: --duration must be >= 20 s")
    if not 0.0 <= args.warmup < 1.0:
        raise InputError("bench soak: --warmup must be in [0, 1)")
    if not args.every > 0:
        raise InputError("bench soak: --every must be > 0")
    with tempfile.TemporaryDirectory(prefix="stillframe-bench-soak-") as tmp:
        report = soak(args.duration, args.warmup, args.every, Path(tmp))
    report["within_limit"] = within_limit(report)
    if args.json:
        emit_json(report)
        return 0
    print(format_table(
        ["process", "warm [MiB]", "end [MiB]", "peak [MiB]", "growth [%]", "net growth [%]"],
        [[name, f"{g['warm_mib']:.1f}", f"{g['end_mib']:.1f}", f"{g['peak_mib']:.1f}",
          f"{g['growth_pct']:.2f}", f"{g['net_growth_pct']:.2f}" if "net_growth_pct" in g else "-"]
         for name, g in report["rss"].items() if g]))
    print(f"{report['steps']} steps, {report['sim_s']:g} s simulated in {report['wall_s']:.0f} s; "
          "counters: " + ", ".join(f"{k} {v}" for k, v in report["counters"].items()))
    print(f"growth after warm-up below {GROWTH_LIMIT_PCT:g} %: "
          f"{'yes' if report['within_limit'] else 'NO'}")
    return 0
