"""``stillframe closed-loop SCENE``: plant, estimator and controller in one process, lock-step.

Prints the steady-state peak reductions per floor beside the reference values the scene carries
(the thesis's, eq. 5.233 and 5.287); ``--json`` prints ``{"reduction_pct": {"displacement": [...],
"velocity": [...]}, "peak_command": ..., "steps": ..., "wall_s": ..., "degraded": false,
"degraded_reasons": [], ...}``. A run whose figures are not the controller's (commands refused, or a
law that ran away and was clipped to the command's bound: :mod:`stillframe.app.run_verdict`, as
``launch`` judges) ends with a warning line giving the reasons.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from stillframe.app.arguments import (
    add_scene_arguments,
    emit_json,
    scene_from_args,
)
from stillframe.app.run_verdict import verdict
from stillframe.errors import InputError
from stillframe.text_table import format_table


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe closed-loop``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("closed-loop", help="run a scene's control loop in one process")
    add_scene_arguments(parser)
    parser.set_defaults(func=run)


def _progress(fraction: float) -> None:
    print(f"\rclosed loop {fraction:6.1%}", end="", file=sys.stderr, flush=True)


def reduction_table(evaluation: dict, reference_d: Sequence[float],
                    reference_v: Sequence[float]) -> str:
    """Floors as rows: our displacement and velocity reductions and the reference ones."""
    red = evaluation["reduction_pct"]
    rows = []
    for i in range(3):
        ref_d = f"{reference_d[i]:.2f}" if len(reference_d) == 3 else "-"
        ref_v = f"{reference_v[i]:.2f}" if len(reference_v) == 3 else "-"
        rows.append([f"floor {i + 1}", f"{red['displacement'][i]:.2f}", ref_d,
                     f"{red['velocity'][i]:.2f}", ref_v])
    return format_table(["", "disp. red. %", "reference %", "vel. red. %", "reference %"], rows)


def run(args: argparse.Namespace) -> int:
    """Run the scene's loop in one process and print the reductions beside the scene's reference
    values (``--json``: the document); exit code 0. A scene without a controller is an
    :class:`~stillframe.errors.InputError`."""
    from stillframe.loop.closed_loop import run_closed_loop

    scene = scene_from_args(args)
    if scene.controller.type == "none":
        raise InputError("controller.type: the scene has no controller (lqg, euk_pendulum, "
                         "euk_floor)")
    show = None if args.json or not sys.stderr.isatty() else _progress
    history = run_closed_loop(scene, progress=show)
    if show:
        print(file=sys.stderr)
    e = history.evaluation
    reasons = verdict(e, {})
    if args.json:
        emit_json({"scene": scene.name, **e, "degraded": bool(reasons),
                   "degraded_reasons": reasons})
        return 0
    ev = scene.evaluation
    print(f"scene {scene.name}: plant {e['plant']['model']} ({e['plant']['integrator']} "
          f"dt = {e['plant']['dt']:g} s), estimator {scene.estimator.type}, controller "
          f"{scene.controller.type} from {scene.controller.start:g} s at "
          f"{scene.sensors.rate_hz:g} Hz")
    baseline = (f"the {ev.window:g} s before the start" if ev.baseline == "before_start"
                else f"the last {ev.window:g} s of a run without control")
    print(f"steady-state peak reductions (last {ev.window:g} s against {baseline}):")
    print(reduction_table(e, ev.reference_displacement_pct, ev.reference_velocity_pct))
    c = e["controller"]
    print(f"peak command {e['peak_command']:.4g}; saturated {c['saturated']}, singular "
          f"{c['singular']}, watchdog {c['watchdog']}; rejected samples "
          f"{e['estimator']['stale'] + e['estimator']['non_finite']}")
    print(f"{e['steps']} steps in {e['wall_s']:.2f} s wall")
    if reasons:
        print("stillframe closed-loop: warning: its figures are not the controller's: "
              f"{'; '.join(reasons)}", file=sys.stderr)
    return 0
