"""``stillframe montecarlo SCENE``: a Monte Carlo study of a scene on Dask (docs/montecarlo.md).

``--vary KEY=DIST`` (repeatable) varies scene keys run by run; ``--runs``, ``--seed`` and
``--what closed-loop|simulate|identify`` choose the study; ``--workers`` sizes the embedded
``LocalCluster``, ``--scheduler tcp://HOST:PORT`` uses an existing cluster instead; ``--only ID``
runs one run alone, in this process, and prints its row. Writes ``runs.csv`` and PNG plots to
``--out``; prints the quantiles of the headline figures, the worst run, the fractions that met
the targets (``stillframe reproduce``'s for the scene, or ``--target``) or went unstable.
``--json`` prints ``{"runs", "failed", "unstable", "quantiles", "fractions", ...}``.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

from stillframe.app.arguments import add_executor_arguments, add_scene_arguments, emit_json, whole
from stillframe.errors import InputError
from stillframe.files import check_output
from stillframe.text_table import format_table

DEFAULT_RUNS = 100
TARGET = re.compile(r"^(displacement|velocity)>=(-?\d+(\.\d*)?)$")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe montecarlo``, its arguments and :func:`run` as its action to ``sub``."""
    from stillframe.studies.montecarlo import WHATS

    parser = sub.add_parser("montecarlo", help="Monte Carlo study of a scene on Dask")
    add_scene_arguments(parser)
    parser.add_argument("--vary", action="append", default=[], metavar="KEY=DIST",
                        help="vary a scene key: ±10%%, normal:5%%, a,b,c or grid:lo:hi:n "
                             "(repeatable)")
    parser.add_argument("--runs", type=whole(1, 1_000_000), default=None, metavar="N",
                        help=f"number of runs (default: the grid's size, else {DEFAULT_RUNS})")
    parser.add_argument("--seed", type=int, default=0, metavar="S", help="study seed")
    parser.add_argument("--what", choices=WHATS, default="closed-loop", help="what one run is")
    add_executor_arguments(parser)
    parser.add_argument("--only", type=int, default=None, metavar="RUN_ID",
                        help="run only this run, here, and print its row")
    parser.add_argument("--target", action="append", default=[], metavar="QUANTITY>=PCT",
                        help="a reduction every floor must reach, e.g. displacement>=50")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="where runs.csv and the plots go (default out/montecarlo/SCENE)")
    parser.set_defaults(func=run)


def _targets(args: argparse.Namespace, scene_name: str) -> list[tuple[str, tuple[int, ...],
                                                                        float]]:
    from stillframe.app.thesis_targets import TARGETS

    targets = [(t.quantity, t.floors, t.minimum_pct) for t in TARGETS if t.scene == scene_name]
    for text in args.target:
        match = TARGET.match(text.replace(" ", ""))
        if not match:
            raise InputError(f"--target {text}: expected displacement>=PCT or velocity>=PCT")
        targets.append((match[1], (1, 2, 3), float(match[2])))
    return targets


def _met(targets: list[tuple[str, tuple[int, ...], float]]) -> Any:
    if not targets:
        return None
    return lambda row: all(row.get(f"reduction_pct.{q}.{f}", float("-inf")) >= pct
                           for q, floors, pct in targets for f in floors)


def _runs(args: argparse.Namespace, combinations: int, discrete_only: bool) -> int:
    if args.runs is None:
        return combinations if discrete_only else DEFAULT_RUNS
    if args.runs < 1:
        raise InputError(f"--runs {args.runs}: must be at least 1")
    return args.runs


def run(args: argparse.Namespace) -> int:
    """Run the study on Dask, write ``runs.csv``, the plots and the summary under ``--out``; exit
    code 0, 130 when interrupted (the finished runs kept), 1 when every run failed."""
    from stillframe.config.scene import load_scene
    from stillframe.studies import report
    from stillframe.studies.executor import run_tasks
    from stillframe.studies.montecarlo import flatten, plan, row, run_one
    from stillframe.studies.vary import parse_vary

    check_output("--out", args.out, folder=True)

    variations = [parse_vary(item) for item in args.vary]
    scene = load_scene(args.scene, args.overrides)
    study = plan(scene, args.overrides, variations, args.seed, args.what)
    n = _runs(args, study.combinations, bool(variations) and all(v.discrete for v in variations))
    targets = _targets(args, scene.name)
    if args.only is not None:
        if not 0 <= args.only < n:
            raise InputError(f"--only {args.only}: runs are numbered 0..{n - 1}")
        outcome = _alone(run_one, study.task(args.only))
        one = row(study.spec(args.only), outcome)
        if args.json:
            emit_json(one)
        else:
            print(format_table(["column", "value"], list(one.items())))
        return 0
    out = args.out or Path("out/montecarlo") / scene.name
    execution = run_tasks(run_one, [study.task(i) for i in range(n)], workers=args.workers,
                          scheduler=args.scheduler, label=f"montecarlo {scene.name}",
                          progress=sys.stderr.isatty())
    rows = [row(study.spec(o.index), o) for o in execution.outcomes]
    table = report.write_table(rows, out / "runs.csv")
    varied = [k for k in rows[0] if k.startswith(tuple(v.key for v in variations))] if rows else []
    nominal = flatten(scene.to_dict())
    context = report.PlotContext(
        scene.name, args.what,
        targets={f"reduction_pct.{q}.{f}": pct for q, floors, pct in targets for f in floors},
        nominal={k: nominal[k] for k in varied if isinstance(nominal.get(k), int | float)})
    plots = report.plot(rows, varied, out, context)
    document = {
        "scene": scene.name, "what": args.what, "seed": args.seed, "requested": n,
        "runs": len(rows), "failed": sum(r["status"] == "failed" for r in rows),
        "unstable": sum(r["status"] == "unstable" for r in rows),
        "interrupted": execution.interrupted, "workers": execution.workers,
        "scheduler": execution.address, "wall_s": execution.wall_s,
        "targets": [f"{q} >= {p:g} % on floors {', '.join(map(str, f))}"
                    for q, f, p in targets],
        "fractions": report.fractions(rows, _met(targets)),
        "quantiles": report.quantiles(rows, args.what),
        "errors": {r["run"]: r["error"] for r in rows if r["error"]},
        "table": str(table), "plots": [str(p) for p in plots],
    }
    if args.json:
        emit_json(document)
    else:
        _print(document)
    if execution.interrupted:
        print(f"stillframe montecarlo: interrupted; kept the {len(rows)} runs that finished",
              file=sys.stderr)
        return 130
    if rows and document["failed"] == len(rows):
        first = min(document["errors"])
        print(f"stillframe montecarlo: error: every run failed (run {first}: "
              f"{document['errors'][first]})", file=sys.stderr)
        return 1
    return 0


def _alone(fn: Any, task: Any) -> Any:
    """One run here, its error recorded as on a worker."""
    from stillframe.studies.executor import Outcome

    try:
        return Outcome(0, fn(task))
    except Exception as exc:  # recorded like a worker's failure, not raised
        return Outcome(0, error=str(exc) or repr(exc), error_type=type(exc).__name__)


def _print(d: dict) -> None:
    print(f"scene {d['scene']}: {d['runs']} of {d['requested']} runs ({d['what']}) on "
          f"{d['workers']} workers in {d['wall_s']:.1f} s; {d['failed']} failed, "
          f"{d['unstable']} unstable")
    if d["quantiles"]:
        keys = [k for k in next(iter(d["quantiles"].values())) if k != "runs"]
        rows = [[name, *(q[k] for k in keys)] for name, q in d["quantiles"].items()]
        print(format_table(["figure", *keys], rows))
    f = d["fractions"]
    met = "no targets" if f["met_targets"] is None else f"{100 * f['met_targets']:.1f} %"
    print(f"met the targets ({'; '.join(d['targets']) or '-'}): {met}; unstable "
          f"{100 * f['unstable']:.1f} %; failed {100 * f['failed']:.1f} %")
    for run_id, error in list(d["errors"].items())[:5]:
        print(f"run {run_id}: {error}")
    print(f"table: {d['table']}")
    for path in d["plots"]:
        print(f"plot: {path}")
