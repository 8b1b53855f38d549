"""``stillframe modes SCENE``: natural frequencies, damping ratios and mode shapes."""

from __future__ import annotations

import argparse

import numpy as np

from stillframe.app.commands.common import (
    add_scene_arguments,
    emit_json,
    scene_from_args,
)
from stillframe.errors import InputError
from stillframe.text_table import format_table


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("modes", help="modes of the scene's model, linearised at rest")
    add_scene_arguments(parser)
    parser.set_defaults(func=run)


def check_finite_modes(table: dict, scene: str) -> None:
    """InputError naming the first mode whose frequency, damping or shape (normalised to floor
    1) is not finite: a rig out of proportion, never NaNs printed with exit 0."""
    for i, (f, z, shape) in enumerate(zip(table["frequencies_hz"], table["damping_ratios"],
                                          table["mode_shapes"], strict=True)):
        if not np.all(np.isfinite([f, z, *shape])):
            raise InputError(f"scene {scene}: mode {i + 1} is not finite (f {f:.4g} Hz, zeta "
                             f"{z:.4g}, shape {', '.join(f'{v:.3g}' for v in shape)}): a rig "
                             "parameter is out of proportion to the others")


def run(args: argparse.Namespace) -> int:
    from stillframe.dynamics.modal_analysis import modal_table
    from stillframe.dynamics.models import build_model
    from stillframe.dynamics.ph import scene_model

    scene = scene_from_args(args)
    try:
        if scene.model.type == "ph":
            table = scene_model.modal_table(scene)
        else:
            table = modal_table(build_model(scene))
    except np.linalg.LinAlgError as exc:
        raise InputError(f"scene {scene.name}: its model has no modes ({exc}); a rig "
                         "parameter is out of proportion to the others") from None
    check_finite_modes(table, scene.name)
    if args.json:
        emit_json(table)
        return 0
    print(f"model {table['model']}: {table['dofs']} DOFs; mode shapes at floors 1..3 and phi, "
          "normalised to floor 1")
    rows = [[i + 1, f, z, *shape] for i, (f, z, shape) in enumerate(
        zip(table["frequencies_hz"], table["damping_ratios"], table["mode_shapes"], strict=True))]
    print(format_table(["mode", "f [Hz]", "zeta", "x1", "x2", "x3", "phi"], rows))
    return 0
