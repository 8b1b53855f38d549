"""``stillframe modes SCENE``: natural frequencies, damping ratios and mode shapes; for a scene
with ``events``, those of the structure after each event too (``after_events`` in the JSON)."""

from __future__ import annotations

import argparse

import numpy as np

from stillframe.app.arguments import (
    add_scene_arguments,
    emit_json,
    scene_from_args,
)
from stillframe.config.scene import Scene
from stillframe.errors import InputError
from stillframe.text_table import format_table


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe modes``, its arguments and :func:`run` as its action to ``sub``."""
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


def scene_modes(scene: Scene) -> dict:
    """The modal table of the scene's model (InputError where it has none)."""
    from stillframe.dynamics.modal_analysis import modal_table
    from stillframe.dynamics.models import build_model
    from stillframe.dynamics.ph import scene_model

    try:
        if scene.model.type == "ph":
            table = scene_model.modal_table(scene)
        else:
            table = modal_table(build_model(scene))
    except np.linalg.LinAlgError as exc:
        raise InputError(f"scene {scene.name}: its model has no modes ({exc}); a rig "
                         "parameter is out of proportion to the others") from None
    check_finite_modes(table, scene.name)
    return table


def run(args: argparse.Namespace) -> int:
    """Print the scene's modal table (:func:`print_table`), and each event's after it; exit code
    0."""
    from stillframe.config.scene import changed_scene, event_changes

    scene = scene_from_args(args)
    table = scene_modes(scene)
    if scene.events:
        table["after_events"] = [
            {"event": i, "time_s": event.time, "changes": event_changes(scene, i),
             **scene_modes(changed_scene(scene, i + 1))}
            for i, event in enumerate(scene.events)]
    if args.json:
        emit_json(table)
        return 0
    print(f"model {table['model']}: {table['dofs']} DOFs; mode shapes at floors 1..3 and phi, "
          "normalised to floor 1")
    print_table(table)
    for after in table.get("after_events", []):
        changed = "; ".join(f"{k} = {v}" for k, v in after["changes"].items())
        print(f"\nafter events[{after['event']}] at {after['time_s']:g} s ({changed}):")
        print_table(after)
    return 0


def print_table(table: dict) -> None:
    """Print the modal table: per mode its frequency [Hz], damping ratio and mode shape over the
    three floors and the pendulum angle."""
    rows = [[i + 1, f, z, *shape] for i, (f, z, shape) in enumerate(
        zip(table["frequencies_hz"], table["damping_ratios"], table["mode_shapes"], strict=True))]
    print(format_table(["mode", "f [Hz]", "zeta", "x1", "x2", "x3", "phi"], rows))
