"""``stillframe simulate SCENE``: open-loop time integration with a summary and time histories.

``--out FILE.npz`` writes arrays ``t``, ``floors`` (N×3, m), ``floor_velocities`` (N×3, m/s),
``floor_accelerations`` (N×3, m/s²), ``phi`` (rad), ``phi_rate`` (rad/s), ``excitation`` (N),
``energy`` (J) and ``scene`` (the validated scene as JSON text); ``--out FILE.csv`` writes the
same columns as CSV with a header line.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import BinaryIO

import numpy as np

from stillframe.app.arguments import (
    add_scene_arguments,
    emit_json,
    scene_and_choice,
    seconds,
)
from stillframe.dynamics.simulation import History, simulate
from stillframe.errors import InputError
from stillframe.files import check_output, open_output
from stillframe.text_table import format_table

CSV_COLUMNS = ("t", "x1", "x2", "x3", "v1", "v2", "v3", "a1", "a2", "a3", "phi", "phi_rate",
               "excitation", "energy")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe simulate``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("simulate", help="integrate a scene open loop and summarise it")
    add_scene_arguments(parser)
    parser.add_argument("--duration", type=seconds, help="override the scene's duration [s]")
    parser.add_argument("--out", type=Path, help="write time histories (.npz or .csv)")
    parser.set_defaults(func=run)


def write_history(history: History, path: Path, scene_json: str) -> None:
    """Write ``history`` to ``path`` as ``.npz`` arrays or ``.csv`` columns (the module's docstring
    lists them), with the resolved scene as JSON; any other suffix is an
    :class:`~stillframe.errors.InputError`."""
    if path.suffix not in (".npz", ".csv"):
        raise InputError(f"--out {path}: use a .npz or .csv file name")
    path.parent.mkdir(parents=True, exist_ok=True)
    with open_output(path, what="history file") as stream:
        _write(history, stream, path.suffix, scene_json)


def _write(history: History, stream: BinaryIO, suffix: str, scene_json: str) -> None:
    if suffix == ".npz":
        np.savez_compressed(stream, t=history.t, floors=history.floors,
                            floor_velocities=history.floor_velocities,
                            floor_accelerations=history.floor_accelerations, phi=history.phi,
                            phi_rate=history.phi_rate, excitation=history.excitation,
                            energy=history.energy, scene=np.array(scene_json))
        return
    table = np.column_stack([history.t, history.floors, history.floor_velocities,
                             history.floor_accelerations, history.phi, history.phi_rate,
                             history.excitation, history.energy])
    np.savetxt(stream, table, delimiter=",", header=",".join(CSV_COLUMNS), comments="")


def _progress(fraction: float) -> None:
    print(f"\rsimulating {fraction:6.1%}", end="", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    """Integrate the scene open-loop, print the summary and write ``--out`` when given; exit code
    0."""
    check_output("--out", args.out)
    if args.duration is not None:   # the scene's checks (steps at most) apply to it
        args.overrides = [*args.overrides, f"duration={args.duration!r}"]
    scene, choice = scene_and_choice(args)
    show = None if args.json or not sys.stderr.isatty() else _progress
    history = simulate(scene, args.duration, progress=show)
    if show:
        print(file=sys.stderr)
    summary = history.summary()
    if choice:
        summary["model_choice"] = f"auto: {choice.reason}"
    if args.out:
        write_history(history, args.out, json.dumps(scene.to_dict()))
        summary["out"] = str(args.out)
    if args.json:
        emit_json({"scene": scene.name, **summary})
        return 0
    print(f"scene {scene.name}: model {summary['model']} ({summary['dofs']} DOFs), "
          f"{summary['integrator']} dt = {summary['dt']:g} s, {summary['steps']} steps")
    rows = [[f"floor {i + 1}", d, a] for i, (d, a) in enumerate(
        zip(summary["peak_displacement_m"], summary["peak_acceleration_m_s2"], strict=True))]
    print(format_table(["", "peak |x| [m]", "peak |a| [m/s^2]"], rows))
    print(f"peak |phi| {summary['peak_phi_rad']:.6g} rad; final energy "
          f"{summary['final_energy_j']:.6g} J")
    if "energy_balance_error" in summary:
        print(f"discrete power balance: largest relative residual "
              f"{summary['energy_balance_error']:.3g}; constraint drift "
              f"{summary['max_constraint_drift']:.3g} m")
    if choice:
        print(f"model choice: auto: {choice.reason}")
    for warning in summary.get("warnings", []):
        print(f"warning: {warning}")
    print(f"wall time {summary['wall_s']:.3f} s, {summary['steps_per_s']:.0f} steps/s "
          "(with recording)")
    if args.out:
        print(f"time histories written to {args.out}")
    return 0
