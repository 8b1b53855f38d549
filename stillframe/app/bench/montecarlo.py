"""``stillframe bench montecarlo``: wall time and efficiency of one Monte Carlo study on 1, 2
and all local workers (embedded ``LocalCluster``) and on a ``dask scheduler`` + 2 ``dask
worker`` processes started here (the stand-in for two machines).

Efficiency on k workers is T1 / (k Tk), T1 the one-worker time of the same run; busy is the
runs' own CPU time over k Tk (the rest is start-up, scheduling and other processes). Wall times
include starting the local cluster (and its workers' first imports); the external cluster is
started before its clock starts, as an existing cluster would be. Every configuration must give
the same table (timing columns aside); the bench says whether it did. A load average above the
core count during the bench gives a warning: other processes then took part of the cores.
"""

from __future__ import annotations

import argparse
import os
import sys

from stillframe.app.arguments import add_json_argument, emit_json, scene_path
from stillframe.errors import InputError
from stillframe.locations import SCENES_DIR
from stillframe.text_table import format_table

DEFAULT_SCENE = SCENES_DIR / "lqg_mismatch.yaml"
SHORT = ["duration=10", "controller.start=5", "evaluation.window=5"]


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench montecarlo``, its arguments and :func:`run` as its action to
    ``benches``."""
    parser = benches.add_parser("montecarlo", help="Monte Carlo scaling: 1, 2, all local "
                                                   "workers and an external 2-worker cluster")
    parser.add_argument("--scene", default=DEFAULT_SCENE, type=scene_path, help="scene (default "
                        "lqg_mismatch)")
    parser.add_argument("--set", dest="overrides", action="append", default=None,
                        metavar="KEY=VALUE", help="scene overrides (default: "
                        + " ".join(SHORT) + ")")
    parser.add_argument("--vary", action="append", default=None, metavar="KEY=DIST",
                        help="default rig.floor_masses=±10%%")
    parser.add_argument("--runs", type=int, default=1000, metavar="N")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def _timing_free(rows: list[dict]) -> list[dict]:
    from stillframe.studies.montecarlo import is_timing

    return [{k: v for k, v in r.items() if not is_timing(k)} for r in rows]


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    from stillframe.config.scene import load_scene
    from stillframe.studies.cluster import local_processes
    from stillframe.studies.executor import run_tasks
    from stillframe.studies.montecarlo import plan, row, run_one
    from stillframe.studies.vary import parse_vary

    if args.runs < 1:
        raise InputError(f"--runs {args.runs}: must be at least 1")
    overrides = SHORT if args.overrides is None else args.overrides
    variations = [parse_vary(v) for v in (args.vary or ["rig.floor_masses=±10%"])]
    scene = load_scene(args.scene, overrides)
    study = plan(scene, overrides, variations, 0, "closed-loop")
    tasks = [study.task(i) for i in range(args.runs)]
    cores = os.cpu_count() or 1
    configs = [("local", k) for k in dict.fromkeys((1, 2, cores))] + [("external", 2)]
    results, tables = [], []
    for kind, k in configs:
        print(f"bench montecarlo: {args.runs} runs on {kind} {k} workers", file=sys.stderr)
        load = os.getloadavg()[0]
        if kind == "local":
            execution = run_tasks(run_one, tasks, workers=k, progress=sys.stderr.isatty())
        else:
            with local_processes(k) as address:
                execution = run_tasks(run_one, tasks, scheduler=address,
                                      progress=sys.stderr.isatty())
        rows = [row(study.spec(o.index), o) for o in execution.outcomes]
        tables.append(_timing_free(rows))
        cpu = sum(r.get("cpu_s", 0.0) for r in rows if r["status"] == "ok")
        results.append({"cluster": kind, "workers": execution.workers,
                        "wall_s": execution.wall_s, "failed": execution.failed,
                        "busy": cpu / (execution.workers * execution.wall_s),
                        "load_average": max(load, os.getloadavg()[0])})
    base = results[0]["wall_s"]
    for r in results:
        r["speedup"] = base / r["wall_s"]
        r["efficiency"] = base / (r["workers"] * r["wall_s"])
    document = {"scene": scene.name, "overrides": overrides, "runs": args.runs,
                "cores": cores, "results": results,
                "same_table": all(t == tables[0] for t in tables)}
    busiest = max(r["load_average"] for r in results)
    if busiest > cores:
        document["warning"] = (f"load average up to {busiest:.1f} on {cores} cores: other "
                               "processes competed for the cores, so the wall times and "
                               "efficiencies understate what free cores give")
    if args.json:
        emit_json(document)
        return 0
    print(f"{args.runs} closed-loop runs of {scene.name} ({' '.join(overrides)}) on "
          f"{cores} cores")
    print(format_table(["cluster", "workers", "wall [s]", "speed-up", "efficiency", "busy",
                        "load avg", "failed"],
                       [[r["cluster"], r["workers"], r["wall_s"], r["speedup"], r["efficiency"],
                         r["busy"], r["load_average"], r["failed"]] for r in results]))
    print(f"same table in every configuration: {'yes' if document['same_table'] else 'NO'}")
    if "warning" in document:
        print(f"warning: {document['warning']}")
    return 0
