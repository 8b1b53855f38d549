"""``stillframe reproduce [SCENE...]``: the thesis's closed-loop results through the three nodes.

Runs each scene (default: the four thesis scenes) in lock-step through sim_node,
estimator_node and controller_node over DDS and prints, per scene, the steady-state peak
reductions per floor beside the thesis's values (eq. 5.233 for LQG, 5.287 for EUK + EKF), then
the targets: LQG ≥ 50 % on every floor, EUK + EKF variant 2 ≥ 85 % on floor-3 displacement.
``--set`` applies to every scene (e.g. shorter runs).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from stillframe import interrupts
from stillframe.app.arguments import add_json_argument, emit_json, scene_path
from stillframe.app.launch_cli import add_launch_arguments, print_evaluation, report_death
from stillframe.app.thesis_targets import TARGETS
from stillframe.config.scene import load_scene
from stillframe.errors import InputError
from stillframe.locations import SCENES_DIR

THESIS_SCENES: tuple[str, ...] = ("thesis_lqg", "thesis_euk_pendulum", "thesis_euk_floor",
                                  "thesis_euk_ekf")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe reproduce``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser(
        "reproduce", help="the thesis's closed-loop tables, each scene through the three nodes",
        description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("scenes", nargs="*", metavar="SCENE", type=scene_path,
                        help="scene files or shipped scene names (default: "
                             + ", ".join(THESIS_SCENES) + ")")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="override a value in every scene (repeatable)")
    add_launch_arguments(parser)
    add_json_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run each scene through the three nodes and print its reductions against the thesis's targets;
    exit code 0, a dead node's code, or 130/143 when interrupted."""
    from stillframe.app.launcher import NodeDiedError, run_scene

    paths = args.scenes or [SCENES_DIR / f"{name}.yaml"
                                               for name in THESIS_SCENES]
    scenes = [load_scene(path, args.overrides) for path in paths]  # all checked before running
    for path, scene in zip(paths, scenes, strict=True):
        if scene.controller.type == "none":
            raise InputError(f"{path}: controller.type: the scene has no controller to evaluate")
    results = []
    with tempfile.TemporaryDirectory(prefix="stillframe-reproduce-") as tmp:
        for i, (path, scene) in enumerate(zip(paths, scenes, strict=True)):
            print(f"[{i + 1}/{len(paths)}] {scene.name} through the three nodes ({args.mode})",
                  file=sys.stderr)
            try:
                result = run_scene(path, args.overrides, out=Path(tmp) / str(i), mode=args.mode,
                                   lockstep_timeout_s=args.lockstep_timeout,
                                   backends=args.backends)
            except NodeDiedError as exc:
                return report_death("reproduce", exc)
            except KeyboardInterrupt as exc:
                print("stillframe reproduce: interrupted; every node stopped", file=sys.stderr)
                return interrupts.exit_code(exc)
            results.append((scene, result.evaluation))
            if not args.json:
                print_evaluation(result.evaluation, scene)
                print()
    checked = [(t, t.met(e["reduction_pct"])) for t in TARGETS for s, e in results
               if s.name == t.scene]
    if args.json:
        emit_json({
            "scenes": [{"scene": s.name, **e,
                        "reference_pct": {"displacement": s.evaluation.reference_displacement_pct,
                                          "velocity": s.evaluation.reference_velocity_pct}}
                       for s, e in results],
            "targets": [{"target": t.describe(), "met": ok} for t, ok in checked],
        })
    else:
        for target, ok in checked:
            print(f"{'met' if ok else 'MISSED'}: {target.describe()}")
    return 0
