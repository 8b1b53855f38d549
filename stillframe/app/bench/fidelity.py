"""``stillframe bench fidelity``: work-precision of every model × integrator × step.

Prints the Pareto-optimal choices per canonical scene, ``--json`` the whole sweep, ``--plots DIR``
one log–log work-precision diagram per scene, ``--write-table FILE`` the table that
``model.type: auto`` reads (with provenance). Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict
from pathlib import Path

from stillframe.app.arguments import add_executor_arguments, add_json_argument, emit_json, seconds
from stillframe.errors import InputError
from stillframe.files import check_output, save_figure
from stillframe.text_table import format_table


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench fidelity``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("fidelity", help="work-precision of models, integrators and steps")
    add_json_argument(parser)
    parser.add_argument("--plots", type=Path, metavar="DIR", help="write PNG diagrams here")
    parser.add_argument("--quick", action="store_true",
                        help="CI-sized run: 4 models, 3 steps, 1 s scenes")
    parser.add_argument("--duration", type=seconds, help="simulated seconds per run")
    parser.add_argument("--write-table", type=Path, metavar="FILE",
                        help="write the model.type: auto table (JSON) here")
    add_executor_arguments(parser)
    parser.set_defaults(func=run)


def _progress(text: str) -> None:
    print(f"bench fidelity: {text}", file=sys.stderr, flush=True)


def plot(result: dict, directory: Path) -> list[Path]:
    """One work-precision diagram per scene: error against CPU time, log–log."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for scene in result["scenes"]:
        fig, ax = plt.subplots(figsize=(7.5, 5.5))
        curves: dict[tuple[str, str], list[tuple[float, float, float]]] = {}
        for p in result["points"]:
            if p["scene"] == scene and p["error"] is not None:
                curves.setdefault((p["model"], p["method"]), []).append(
                    (p["cpu_per_s"], max(p["error"], 1e-16), p["dt"]))
        models = list(dict.fromkeys(m for m, _ in curves))
        for (model, method), pts in curves.items():
            pts.sort(key=lambda x: -x[2])
            ax.loglog([c for c, _, _ in pts], [e for _, e, _ in pts],
                      "o-" if method == "midpoint" else "s--", color=f"C{models.index(model)}",
                      label=f"{model} {method}", ms=4)
        front = result["pareto"][scene]
        ax.loglog([p["cpu_per_s"] for p in front], [p["error"] for p in front], "k:", lw=2,
                  label="Pareto front")
        ref = result["reference"]
        ax.set_title(f"{scene}: error vs {ref['model']} {ref['method']} dt={ref['dt']:g} s")
        ax.set_xlabel("CPU time per simulated second [s]")
        ax.set_ylabel("max relative error of x1..x3, phi [-]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
        path = directory / f"fidelity_{scene}.png"
        fig.tight_layout()
        save_figure(fig, path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    from stillframe.dynamics.ph.energy_drift import FREE_VIBRATION, energy_drift_rows
    from stillframe.fidelity.auto_model import write_table
    from stillframe.fidelity.work_precision import GRID_DT, sweep

    check_output("--plots", args.plots, folder=True)
    check_output("--write-table", args.write_table)
    if args.duration is not None:
        grid_steps = args.duration / GRID_DT
        if args.duration <= 0 or abs(grid_steps - round(grid_steps)) > 1e-9:
            raise InputError(f"--duration: must be a positive multiple of {GRID_DT:g} s "
                             f"(got {args.duration:g})")
    from stillframe.studies.executor import mapper

    result = sweep(quick=args.quick, duration=args.duration, progress=_progress,
                   mapper=mapper(args.workers, args.scheduler, "bench fidelity"))
    result["energy_drift"] = [asdict(r) for r in energy_drift_rows(
        duration=0.5 if args.quick else 2.0, progress=_progress)]
    if args.plots:
        result["plots"] = [str(p) for p in plot(result, args.plots)]
    if args.write_table:
        write_table(result, args.write_table, sys.argv)
        result["table"] = str(args.write_table)
    if args.json:
        emit_json(result)
        return 0
    ref = result["reference"]
    print(f"reference: {ref['model']} {ref['method']} dt={ref['dt']:g} s, {ref['check']}; "
          f"{result['duration_s']:g} s per run; error = max over x1..x3, phi of "
          "max|y - y_ref| / max|y_ref|")
    for scene, info in ref["per_scene"].items():
        print(f"  {scene}: reference error estimate {info['richardson_error']:.2g}")
    for scene, front in result["pareto"].items():
        print(f"\nPareto-optimal choices, scene {scene}:")
        rows = [[p["model"], p["dofs"], p["method"], p["dt"], p["error"], p["cpu_per_s"]]
                for p in front]
        print(format_table(["model", "DOFs", "method", "dt [s]", "error", "CPU s / sim s"],
                           rows))
    print(f"\nEnergy drift, undamped free vibration ({' '.join(FREE_VIBRATION)}), pH rows "
          "(docs/port-hamiltonian.md):")
    rows = [[r["model"], r["method"], r["dt"], r["energy_drift"], r["error_vs_fe40"],
             r["cpu_per_s"], r["note"]] for r in result["energy_drift"]]
    print(format_table(["model", "method", "dt [s]", "max |dE|/E0", "error vs fe40",
                        "CPU s / sim s", "note"], rows))
    for path in result.get("plots", []):
        print(f"plot: {path}")
    if "table" in result:
        print(f"model: auto table written to {result['table']}")
    return 0
