"""``stillframe bench scaling``: cost per lock-step sample against the size of the plant.

The LQG scene (``scenes/thesis_lqg.yaml``: Kalman filter and LQR on the identified design
model, 32 Hz, 32 midpoint substeps per sample) with each plant of :data:`PLANTS`: the identified
linear model (``plant.model: file``), then the scene's nonlinear lumped, FE (3, 10, 40 elements
per column) and modal (3, 12 column modes) models. For each: microseconds per sample of the
loop in one process (``closed-loop``), of the plant alone (``sample`` + ``advance``), the
plant's share of the one-process sample, and through the three node processes in lock-step.
The design model, hence the estimator and controller cost, is the same in every row, so the
rows differ by the plant alone: where its share passes one half, the plant kernel dominates.

Times: one-process figures are the loop's CPU time (without the set-up), the least of
:data:`REPEATS` runs (on a shared machine the minimum is the run least disturbed) after one run
that compiles the kernels; the node figure is sim_node's loop time (wall), one run. Ratios are
against the first row, measured in the same run.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.arguments import add_json_argument, emit_json, seconds
from stillframe.errors import InputError
from stillframe.locations import SCENES_DIR
from stillframe.middleware import api
from stillframe.text_table import format_table

SCENE = SCENES_DIR / "thesis_lqg.yaml"
REPEATS = 3
#: (label, overrides of the plant); the nonlinear models with modal damping (Rayleigh damping
#: of the identified alpha, beta is negative on the FE and modal models' high modes)
PLANTS: tuple[tuple[str, list[str]], ...] = (
    ("identified (file)", []),
    ("lumped", ["model.type=lumped"]),
    ("FE 3", ["model.type=fe", "model.elements_per_column=3"]),
    ("FE 10", ["model.type=fe", "model.elements_per_column=10"]),
    ("FE 40", ["model.type=fe", "model.elements_per_column=40"]),
    ("modal 3", ["model.type=modal", "model.modes=3"]),
    ("modal 12", ["model.type=modal", "model.modes=12"]),
)


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench scaling``, its arguments and :func:`run` as its action to
    ``benches``."""
    parser = benches.add_parser("scaling", help="cost per lock-step sample against plant size",
                                description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--duration", type=seconds, default=4.0, metavar="S",
                        help="simulated seconds per run (default 4: 128 samples)")
    parser.add_argument("--no-nodes", action="store_true",
                        help="one process only (no node processes)")
    parser.add_argument("--backend", default="dds", choices=api.BACKENDS,
                        help="middleware of the node runs (default dds)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def overrides(plant: list[str], duration: float) -> list[str]:
    """The LQG scene for ``duration`` s with ``plant``; control from half-time, its command
    limited so that the identified design cannot drive a nonlinear plant away."""
    scene_plant = ["plant.model=scene", "damping.model=modal", *plant] if plant else []
    return [f"duration={duration:g}", f"controller.start={duration / 2:g}",
            f"evaluation.window={duration / 4:g}", "controller.limit=0.002", *scene_plant]


def one_process(sets: list[str]) -> dict[str, Any]:
    """µs per sample of the one-process loop and of the plant alone, and the plant's size."""
    from stillframe.config.scene import load_scene
    from stillframe.loop.closed_loop import run_closed_loop
    from stillframe.plant.frame_plant import make_plant

    scene = load_scene(SCENE, sets)
    steps = run_closed_loop(scene).evaluation["steps"]          # compiles the kernels
    loop = min(run_closed_loop(scene).evaluation["loop_cpu_s"] for _ in range(REPEATS))

    def plant_alone() -> float:
        plant = make_plant(scene)
        zero = np.zeros(2)
        start = time.process_time()
        for _ in range(steps):
            plant.sample()
            plant.advance(zero)
        return time.process_time() - start

    alone = min(plant_alone() for _ in range(REPEATS))
    plant = make_plant(scene)
    return {"states": int(plant.x.size), "steps": steps, "substeps": plant.substeps,
            "one_process_us": 1e6 * loop / steps, "plant_us": 1e6 * alone / steps}


def through_nodes(sets: list[str], out: Path, backend: str) -> dict[str, Any]:
    """µs per sample of sim_node's lock-step loop with the three node processes, and whether
    the run completed."""
    from stillframe.app.launcher import run_scene

    result = run_scene(SCENE, sets, out=out, mode="lockstep", backends=[backend]).evaluation
    return {"nodes_us": 1e6 * result["wall_s"] / result["steps"],
            "complete": result.get("complete")}


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    if not args.duration >= 1.0:
        raise InputError("bench scaling: --duration must be >= 1 s")
    if not args.no_nodes:
        api.check_backend(args.backend, f"bench scaling --backend {args.backend}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="stillframe-bench-scaling-") as tmp:
        for i, (label, plant) in enumerate(PLANTS):
            sets = overrides(plant, args.duration)
            print(f"[{i + 1}/{len(PLANTS)}] {label}: one process", file=sys.stderr)
            row = {"plant": label, "overrides": sets, **one_process(sets)}
            row["plant_share"] = row["plant_us"] / row["one_process_us"]
            if not args.no_nodes:
                print(f"[{i + 1}/{len(PLANTS)}] {label}: three nodes, lock-step", file=sys.stderr)
                row.update(through_nodes(sets, Path(tmp) / str(i), args.backend))
            rows.append(row)
    base = rows[0]
    for row in rows:
        row["one_process_over_first"] = row["one_process_us"] / base["one_process_us"]
        if "nodes_us" in row:
            row["nodes_over_first"] = row["nodes_us"] / base["nodes_us"]
            row["nodes_over_one_process"] = row["nodes_us"] / row["one_process_us"]
    if args.json:
        emit_json({"scene": SCENE.name, "duration_s": args.duration, "rows": rows})
        return 0
    nodes = not args.no_nodes
    print(format_table(
        ["plant", "states", "one process [us]", "plant alone [us]", "plant share",
         "x first row",
         *(["nodes [us]", "x first row", "nodes / one process", "complete"] if nodes else [])],
        [[r["plant"], r["states"], f"{r['one_process_us']:.0f}", f"{r['plant_us']:.0f}",
          f"{100 * r['plant_share']:.0f} %", f"{r['one_process_over_first']:.2f}",
          *([f"{r['nodes_us']:.0f}", f"{r['nodes_over_first']:.2f}",
             f"{r['nodes_over_one_process']:.2f}", r["complete"]] if nodes else [])]
         for r in rows]))
    return 0
