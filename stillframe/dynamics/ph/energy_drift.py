"""Energy drift of the models × integrators on an undamped free vibration: the pH rows of
``stillframe bench fidelity``.

Scene: no damping (structure and hinge), no excitation, floors released from 5/10/15 mm with a
1 rad pendulum swing. Per run: max_t |E(t) − E(0)| / E(0) (E the model's stored energy above
rest; for the pHDAE its Hamiltonian H), the largest floor/φ deviation from the FE-40 midpoint run
at the same step (relative to its peaks, as in the sweep), and the CPU time per simulated
second. The compiled kernels run the FrameModel rows, the compiled AVF midpoint step
(:mod:`stillframe.dynamics.ph.frame_step`) the pHDAE.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from stillframe.config.scene import Scene, scene_from_dict
from stillframe.dynamics.kernels import CompiledFrame
from stillframe.dynamics.models import build_model
from stillframe.dynamics.ph.scene_model import initial_state, scene_frame
from stillframe.dynamics.simulation import initial_state as frame_initial_state
from stillframe.dynamics.stability import rk4_stable_step

FREE_VIBRATION = ["damping.model=none", "rig.pendulum.hinge_damping=0", "excitation.type=none",
                  "initial.floors=[0.005, 0.01, 0.015]", "initial.phi=1.0"]
ROWS = (("lumped", "rk4"), ("lumped", "midpoint"), ("fe3", "rk4"), ("fe3", "midpoint"),
        ("ph2", "avf-midpoint"))
MODEL_OVERRIDES = {"lumped": ["model.type=lumped"],
                   "fe3": ["model.type=fe", "model.elements_per_column=3"],
                   "fe40": ["model.type=fe", "model.elements_per_column=40"],
                   "ph2": ["model.type=ph", "model.elements_per_column=2"]}


@dataclass(frozen=True)
class DriftRow:
    model: str
    method: str
    dt: float
    energy_drift: float | None
    error_vs_fe40: float | None
    cpu_per_s: float | None
    note: str = ""


def _scene(model: str, duration: float) -> Scene:
    return scene_from_dict({"name": f"free-{model}"},
                           [*FREE_VIBRATION, *MODEL_OVERRIDES[model], f"duration={duration}"])


def _frame_run(model_name: str, method: str, dt: float, duration: float,
               ) -> tuple[np.ndarray, np.ndarray, float]:
    """Outputs (x1..x3, φ), energies and CPU seconds of a FrameModel run."""
    scene = _scene(model_name, duration)
    model = build_model(scene)
    compiled = CompiledFrame(model)
    x0 = frame_initial_state(model, scene.initial)
    n = round(duration / dt)
    compiled.run(method, x0, dt, 1)  # compile outside the clock
    start = time.process_time()
    states = compiled.run(method, x0, dt, n)
    cpu = time.process_time() - start
    nd = model.n_dof
    energy = np.array([model.energy(x[:nd], x[nd:]) for x in states])
    return states[:, [*model.floor_index, model.phi_index]], energy, cpu


def _ph_run(dt: float, duration: float) -> tuple[np.ndarray, np.ndarray, float]:
    scene = _scene("ph2", duration)
    fs = scene_frame(scene)
    stepper = fs.stepper(dt)
    z = stepper.reduce(initial_state(fs.system, scene))
    n = round(duration / dt)
    states = np.empty((n + 1, z.size))
    states[0] = z
    zero = np.zeros(4)
    stepper.run(z.copy(), np.zeros((1, 3)), zero, zero)  # compile outside the clock
    start = time.process_time()
    stepper.run(z, np.zeros((n, 3)), zero, zero, states=states[1:])
    cpu = time.process_time() - start
    r = stepper.readings(states)
    return np.column_stack([r["floors"], r["phi"]]), stepper.energies(states), cpu


def energy_drift_rows(duration: float = 2.0, dt: float = 2e-3,
                      progress: Callable[[str], None] | None = None) -> list[DriftRow]:
    say = progress or (lambda _text: None)
    say(f"energy drift: fe40 midpoint dt={dt:g}")
    reference, _, _ = _frame_run("fe40", "midpoint", dt, duration)
    scale = np.max(np.abs(reference), axis=0)
    rows = []
    for model, method in ROWS:
        if method == "rk4":
            limit = rk4_stable_step(build_model(_scene(model, duration)))
            if dt > limit:
                rows.append(DriftRow(model, method, dt, None, None, None,
                                     f"beyond RK4 stability limit {limit:.3g} s"))
                continue
        say(f"energy drift: {model} {method} dt={dt:g}")
        y, energy, cpu = (_ph_run(dt, duration) if model == "ph2"
                          else _frame_run(model, method, dt, duration))
        drift = float(np.max(np.abs(energy - energy[0])) / energy[0])
        error = float(np.max(np.max(np.abs(y - reference), axis=0) / scale))
        rows.append(DriftRow(model, method, dt, drift, error, cpu / duration))
    return rows
