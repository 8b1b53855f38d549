"""``stillframe bench controllers``: the control laws side by side (docs/controllers.md).

Two cases, each through the one-process closed loop (:func:`run_closed_loop`, the nodes' numbers):

- ``thesis``: ``scenes/thesis_lqg.yaml`` as it is (linear identified plant, no torque limit);
- ``torque-limited``: the same scene on the rig's nonlinear lumped plant with the lumped design
  model and ``actuators.torque_limit=2`` (commands beyond it clipped).

Laws: LQG, LQG with anti-windup (``controller.anti_windup``), MPC, passivity, EUK (variant 1, on
the pendulum), each with the scene's estimator. Columns: the steady-state peak displacement
reduction of each floor, the peak torque, the limit violations (commands the law asked beyond
the limit, which the supervisor then clipped), the largest pendulum angle after the start (over
π: it went over the top), and the law's CPU time per sample (p50, and its ratio to LQG's in
the same run).

Then the MPC at 32 Hz and at 1 kHz on the torque-limited case (the scene's whole run; --quick:
8 s), each on its prediction grid: the solve time (the solver's own, OSQP ``info.solve_time``,
and the whole law call), p50 and p99 against the period, the fallbacks, and the reductions.
Times are measured on a shared machine: noisy, compare within a run.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from stillframe.app.arguments import add_json_argument, emit_json
from stillframe.config.scene import load_scene
from stillframe.errors import StillframeError
from stillframe.locations import SCENES_DIR
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.text_table import format_table

SCENE = SCENES_DIR / "thesis_lqg.yaml"
CASES = {
    "thesis": [],
    "torque-limited": ["plant.model=scene", "model.type=lumped", "design.model=lumped",
                       "actuators.torque_limit=2"],
}
LAWS = {
    "LQG": ["controller.type=lqg"],
    "LQG anti-windup": ["controller.type=lqg", "controller.anti_windup=true"],
    "MPC": ["controller.type=mpc"],
    "passivity": ["controller.type=passivity"],
    "EUK": ["controller.type=euk_pendulum"],
}
#: the MPC's timing runs: (label, rate [Hz], overrides); the scene's duration (--quick: 8 s)
RATES = (("32 Hz", 32.0, []), ("1 kHz", 1024.0, ["sensors.rate_hz=1024"]))
QUICK_TIMING = ["duration=8", "controller.start=4", "evaluation.window=2"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench controllers``, its arguments and :func:`run` as its action to
    ``sub``."""
    parser = sub.add_parser("controllers", help="LQG, anti-windup LQG, MPC, passivity, EUK: "
                            "reductions, peak torque, limit violations, compute time")
    add_json_argument(parser)
    parser.add_argument("--quick", action="store_true",
                        help="shorter runs (duration 30 s, control from 15 s)")
    parser.set_defaults(func=run)


def _row(case: str, law: str, overrides: list[str]) -> dict:
    history = run_closed_loop(load_scene(SCENE, overrides))
    e = history.evaluation
    after = history.t >= load_scene(SCENE, overrides).controller.start
    compute = e["controller_compute_s"]
    return {"case": case, "law": law,
            "reduction_pct": e["reduction_pct"]["displacement"],
            "peak_torque": e["peak_command"],
            "violations": e["controller"]["saturated"],
            "max_angle": float(np.max(np.abs(history.truth[after, 3]))),
            "compute_p50_s": compute.get("cpu_p50", math.nan),
            "subdivisions": e["plant"]["subdivisions"]}


def _error_row(case: str, law: str, error: Exception) -> dict:
    return {"case": case, "law": law, "error": str(error)}


def measure(quick: bool) -> dict:
    """Every law of :data:`LAWS` on every case of :data:`CASES` through the one-process loop, and
    the MPC's solve time at each rate of :data:`RATES`, as the benchmark's document (``quick``:
    shorter runs)."""
    short = ["duration=30", "controller.start=15", "evaluation.window=10"] if quick else []
    rows = []
    for case, case_overrides in CASES.items():
        for law, law_overrides in LAWS.items():
            overrides = [*case_overrides, *law_overrides, *short]
            try:
                rows.append(_row(case, law, overrides))
            except StillframeError as exc:  # a run that fails is a row of the table
                rows.append(_error_row(case, law, exc))
    for case in CASES:
        base = next(r for r in rows if r["case"] == case and r["law"] == "LQG")
        for r in rows:
            if r["case"] == case and "error" not in r and "error" not in base:
                r["compute_vs_lqg"] = r["compute_p50_s"] / base["compute_p50_s"]
    from stillframe.control.mpc import PredictionGrid  # OSQP only where the MPC runs

    timing = []
    for label, rate, overrides in RATES:
        scene = load_scene(SCENE, [*CASES["torque-limited"], "controller.type=mpc", *overrides,
                                   *(QUICK_TIMING if quick else [])])
        history = run_closed_loop(scene)
        stats = history.evaluation["controller_compute_s"]
        period = 1.0 / rate
        c = scene.controller
        grid = PredictionGrid.of(c.horizon_s, c.prediction_steps, period)
        after = history.t >= c.start
        timing.append({"rate": label, "period_s": period, **stats,
                       "grid": {"steps": grid.steps, "samples_per_step": grid.samples},
                       "max_angle": float(np.max(np.abs(history.truth[after, 3]))),
                       "cpu_p99_over_period": stats["cpu_p99"] / period,
                       "wall_p99_over_period": stats["p99"] / period,
                       "samples": int(np.count_nonzero(after)),   # controlled ones
                       "fallbacks": history.evaluation["controller"]["fallback"],
                       "reduction_pct": history.evaluation["reduction_pct"]["displacement"],
                       "peak_torque": history.evaluation["peak_command"]})
    label, _, overrides = RATES[-1]                # the anti-windup LQG beside it at 1 kHz
    beside = _row(f"torque-limited {label}", "LQG anti-windup",
                  [*CASES["torque-limited"], *LAWS["LQG anti-windup"], *overrides,
                   *(QUICK_TIMING if quick else [])])
    return {"rows": rows, "mpc_timing": timing, "anti_windup_1khz": beside}


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.0f}"


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    result = measure(args.quick)
    if args.json:
        emit_json(result)
        return 0
    for case in CASES:
        print(f"\n{case}: steady-state peak displacement reduction per floor (%), control "
              "from the scene's start")
        table = []
        for r in (r for r in result["rows"] if r["case"] == case):
            if "error" in r:
                table.append([r["law"], "failed: " + r["error"][:60], "", "", "", "", "", ""])
                continue
            red = [f"{x:.1f}" if abs(x) < 1e4 else f"{x:.1e}" for x in r["reduction_pct"]]
            table.append([r["law"], *red, f"{r['peak_torque']:.3g}", r["violations"],
                          f"{r['max_angle']:.3g}",
                          f"{_us(r['compute_p50_s'])} ({r['compute_vs_lqg']:.1f}x)"])
        print(format_table(["law", "floor 1", "floor 2", "floor 3", "peak torque [N m]",
                            "limit violations", "max |phi| [rad]", "CPU us/sample p50 (vs LQG)"],
                           table))
    print("\nMPC on the torque-limited case: time per sample against the period "
          "(shared machine)")
    print(format_table(
        ["rate", "grid", "period [us]", "CPU p50", "CPU p99", "CPU p99/period", "wall p50",
         "wall p99", "wall p99/period", "OSQP p50", "OSQP p99", "fallbacks / controlled samples"],
        [[t["rate"], f"{t['grid']['steps']} x {t['grid']['samples_per_step']}",
          _us(t["period_s"]), _us(t["cpu_p50"]), _us(t["cpu_p99"]),
          f"{t['cpu_p99_over_period']:.2f}", _us(t["p50"]), _us(t["p99"]),
          f"{t['wall_p99_over_period']:.2f}", _us(t["solve_p50"]), _us(t["solve_p99"]),
          f"{t['fallbacks']} / {t['samples']}"] for t in result["mpc_timing"]]))
    print("grid: prediction steps x samples per step. CPU: the law's thread CPU time per sample "
          "(the solve plus its Python set-up); wall adds what other processes on this shared "
          "machine took meanwhile (4 ms scheduler ticks); OSQP: the solver's own wall time. "
          "Times in us.")
    print("\nThe same runs: steady-state peak displacement reduction per floor (%), with the "
          "anti-windup LQG at 1 kHz beside them")
    beside = result["anti_windup_1khz"]
    print(format_table(
        ["law", "rate", "floor 1", "floor 2", "floor 3", "peak torque [N m]", "max |phi| [rad]"],
        [[law, rate, *(f"{x:.1f}" for x in r["reduction_pct"]), f"{r['peak_torque']:.3g}",
          f"{r['max_angle']:.3g}"]
         for law, rate, r in [*(("MPC", t["rate"], t) for t in result["mpc_timing"]),
                              ("LQG anti-windup", RATES[-1][0], beside)]]))
    return 0
