"""``stillframe bench speed``: compiled kernels against the numpy integrators, in one run.

- lumped model, RK4 at 1 ms: steps per second, compiled vs
:func:`stillframe.dynamics.integrators.integrate`;
- FE model with 40 elements per column, implicit midpoint at 1 ms: real-time factor (simulated
  seconds per CPU second), compiled banded vs the generic dense :class:`ImplicitMidpoint`;
- cost of one compiled implicit step against the number of DOFs (FE 10…200 elements per
  column), with the fitted exponent of cost ∝ DOFs^p;
- the port-Hamiltonian plant against the FE midpoint plant on the same mesh (3 elements per
  column, ``thesis_fe`` at 32 Hz, 32 steps per sample): CPU time per integrator step of the
  plant's sample + advance, and the ratio ``ph_over_fe_cost`` (target ≤ 3); and the pH plant at
  1 kHz (one step per sample) as a real-time factor (target ≥ 1).

Times are CPU times (``time.process_time``) of one process on one core, the least of
:data:`REPEATS` runs for every path alike.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from stillframe.app.arguments import add_json_argument, emit_json
from stillframe.text_table import format_table

MESHES = (10, 20, 40, 100, 200)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench speed``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("speed", help="compiled kernels vs numpy integrators (ratios)")
    add_json_argument(parser)
    parser.add_argument("--quick", action="store_true", help="fewer steps and meshes")
    parser.set_defaults(func=run)


REPEATS = 5


def _cpu(work, repeats: int = REPEATS) -> float:
    """The least CPU time of ``repeats`` runs (timeit's convention: on a shared machine the
    minimum is the run least disturbed by other processes)."""
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        work()
        best = min(best, time.process_time() - start)
    return best


def _setup(overrides: list[str]):
    from stillframe.config.scene import scene_from_dict
    from stillframe.dynamics.excitation import floor_load
    from stillframe.dynamics.kernels import CompiledFrame
    from stillframe.dynamics.models import build_model
    from stillframe.dynamics.simulation import initial_state
    from stillframe.dynamics.systems import MechanicalSystem

    scene = scene_from_dict({"name": "speed"}, ["excitation.type=harmonics", *overrides])
    model = build_model(scene)
    load = floor_load(scene.excitation, scene.duration)
    frame = CompiledFrame(model)
    return model, load, frame, MechanicalSystem(model, load), initial_state(model, scene.initial)


def measure(quick: bool = False) -> dict:
    """The compiled kernels against the numpy integrators, each measured in CPU time in this run:
    lumped RK4 steps per second and FE-40 implicit-midpoint real-time factors, with their ratios and
    targets (``quick``: fewer steps)."""
    from stillframe.dynamics.integrators import RK4, ImplicitMidpoint, integrate

    say = lambda text: print(f"bench speed: {text}", file=sys.stderr, flush=True)  # noqa: E731
    h = 1e-3
    say("lumped RK4")
    _, load, frame, system, x0 = _setup([])
    frame.run("rk4", x0, h, 2, load=load)
    n_fast, n_slow = (200_000, 5_000) if quick else (1_000_000, 10_000)
    fast = n_fast / _cpu(lambda: frame.run("rk4", x0, h, n_fast, load=load, stride=1000))
    slow = n_slow / _cpu(lambda: integrate(system, x0, h, n_slow, RK4()))
    rk4 = {"compiled_steps_per_s": fast, "numpy_steps_per_s": slow, "ratio": fast / slow,
           "target_steps_per_s": 1e6}
    say("FE 40 implicit midpoint")
    fe = ["model.type=fe", "damping.model=modal"]
    _, load, frame, system, x0 = _setup([*fe, "model.elements_per_column=40"])
    frame.run("midpoint", x0, h, 2, load=load)
    n_fast, n_slow = (2_000, 50) if quick else (10_000, 100)
    fast = n_fast * h / _cpu(lambda: frame.run("midpoint", x0, h, n_fast, load=load, stride=100))
    slow = n_slow * h / _cpu(lambda: integrate(system, x0, h, n_slow, ImplicitMidpoint()))
    fe40 = {"compiled_real_time_factor": fast, "numpy_real_time_factor": slow,
            "ratio": fast / slow, "target_real_time_factor": 10.0}
    rows = []
    for n_e in MESHES[:3] if quick else MESHES:
        say(f"implicit step cost, FE {n_e} elements per column")
        model, load, frame, _, x0 = _setup([*fe, f"model.elements_per_column={n_e}"])
        frame.run("midpoint", x0, h, 2, load=load)
        n = 2_000 if quick else 10_000
        per_step = _cpu(lambda: frame.run("midpoint", x0, h, n, load=load, stride=100)) / n  # noqa: B023
        rows.append({"elements_per_column": n_e, "dofs": model.n_dof, "us_per_step": 1e6 * per_step,
                     "bandwidth": int(frame.banded_step_matrix(h)[0])})
    dofs = np.array([r["dofs"] for r in rows], float)
    cost = np.array([r["us_per_step"] for r in rows])
    exponent = float(np.polyfit(np.log(dofs), np.log(cost), 1)[0])
    say("pH plant against the FE midpoint plant, 3 elements per column")
    return {"lumped_rk4": rk4, "fe40_midpoint_1ms": fe40,
            "implicit_step_cost": {"rows": rows, "exponent": exponent},
            **plant_costs(quick)}


PH_TARGET_RATIO = 3.0


def _plant_step_us(overrides: list[str], seconds: float) -> tuple[float, float]:
    """CPU µs per integrator step and per sample period of a plant's sample + advance."""
    from stillframe.config.scene import load_scene
    from stillframe.locations import SCENES_DIR
    from stillframe.plant.frame_plant import make_plant

    scene = load_scene(SCENES_DIR / "thesis_fe.yaml", overrides)
    plant = make_plant(scene)
    plant.warm_up()
    periods = round(seconds * scene.sensors.rate_hz)
    command = np.zeros(2)

    def work() -> None:
        for _ in range(periods):
            plant.sample()
            plant.advance(command)

    per_period = _cpu(work) / periods
    return 1e6 * per_period / plant.substeps, 1e6 * per_period


def plant_costs(quick: bool = False) -> dict:
    """The pH plant's step against the FE midpoint plant's on the same mesh, and the pH plant at
    1 kHz (the ``ph`` entry of :func:`measure`)."""
    mesh = ["model.elements_per_column=3", "integrator.method=midpoint", "sensors.rate_hz=32",
            "integrator.dt=9.765625e-4"]
    seconds = 2.0 if quick else 10.0
    fe_us, _ = _plant_step_us([*mesh, "model.type=fe"], seconds)
    ph_us, _ = _plant_step_us([*mesh, "model.type=ph"], seconds)
    fast = [*mesh, "model.type=ph", "sensors.rate_hz=1000", "integrator.dt=1e-3"]
    _, period_us = _plant_step_us(fast, seconds / 4)
    return {"fe3_midpoint_plant": {"us_per_step": fe_us},
            "ph": {"elements_per_column": 3, "us_per_step": ph_us,
                   "ph_over_fe_cost": ph_us / fe_us, "target_ratio": PH_TARGET_RATIO,
                   "rate_1khz_us_per_period": period_us,
                   "rate_1khz_real_time_factor": 1e3 / period_us}}


def run(args: argparse.Namespace) -> int:
    """Print :func:`measure`'s figures (``--json``: its document); exit code 0."""
    result = measure(args.quick)
    if args.json:
        emit_json(result)
        return 0
    r, f, c = result["lumped_rk4"], result["fe40_midpoint_1ms"], result["implicit_step_cost"]
    print(f"lumped model, RK4, dt = 1 ms (CPU time, one core, best of {REPEATS}):")
    print(format_table(["path", "steps/s"], [["compiled (numba)", r["compiled_steps_per_s"]],
                                             ["numpy integrate()", r["numpy_steps_per_s"]]]))
    print(f"ratio {r['ratio']:.0f}x; target 1e6 steps/s: "
          f"{'met' if r['compiled_steps_per_s'] >= 1e6 else 'NOT met'}")
    print("\nFE 40 elements per column, implicit midpoint, dt = 1 ms:")
    print(format_table(["path", "x real time"],
                       [["compiled banded", f["compiled_real_time_factor"]],
                        ["numpy ImplicitMidpoint", f["numpy_real_time_factor"]]]))
    print(f"ratio {f['ratio']:.0f}x; target 10x real time: "
          f"{'met' if f['compiled_real_time_factor'] >= 10 else 'NOT met'}")
    print("\ncost of one compiled implicit step:")
    print(format_table(["elements/column", "DOFs", "half-bandwidth", "us/step"],
                       [[x["elements_per_column"], x["dofs"], x["bandwidth"], x["us_per_step"]]
                        for x in c["rows"]]))
    print(f"fitted cost ~ DOFs^{c['exponent']:.2f} (linear = 1)")
    ph, fe = result["ph"], result["fe3_midpoint_plant"]
    print("\nplant step, 3 elements per column, thesis_fe at 32 Hz (sample + advance per step):")
    print(format_table(["plant", "us/step"], [["FE, compiled midpoint", fe["us_per_step"]],
                                              ["pH, compiled AVF midpoint", ph["us_per_step"]]]))
    print(f"ratio pH/FE {ph['ph_over_fe_cost']:.2f}; target <= {PH_TARGET_RATIO:g}: "
          f"{'met' if ph['ph_over_fe_cost'] <= PH_TARGET_RATIO else 'NOT met'}")
    print(f"pH plant at 1 kHz (one step per sample): {ph['rate_1khz_us_per_period']:.1f} us per "
          f"period, {ph['rate_1khz_real_time_factor']:.1f}x real time; target 1x: "
          f"{'met' if ph['rate_1khz_real_time_factor'] >= 1 else 'NOT met'}")
    return 0
