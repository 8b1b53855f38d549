"""Open-loop simulation of a scene: model, loads, integrator, recorded time histories."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from stillframe.config.scene import Initial, Scene
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.integrators import (
    ADAPTIVE,
    Subdivision,
    integrate,
    make_integrator,
    reference_solution,
)
from stillframe.dynamics.kernels import compiled_integrate, compiles
from stillframe.dynamics.models import FrameModel, build_model
from stillframe.dynamics.ph import scene_model as ph_scene
from stillframe.dynamics.stability import check_rk4_step, drift_warning
from stillframe.dynamics.systems import MechanicalSystem
from stillframe.errors import InputError

__all__ = ["History", "Progress", "initial_state", "simulate"]

log = logging.getLogger("stillframe.dynamics.simulation")

Progress = Callable[[float], None]


def initial_state(model: FrameModel, initial: Initial) -> np.ndarray:
    """[q, q̇] from floor displacements/velocities and φ, φ̇; inner DOFs in static equilibrium."""
    q = np.zeros(model.n_dof)
    v = np.zeros(model.n_dof)
    n = model.n_struct
    q[:n] = model.static_fill(np.asarray(initial.floors))
    v[:n] = model.static_fill(np.asarray(initial.floor_velocities))
    q[n], v[n] = initial.phi, initial.phi_rate
    return np.concatenate([q, v])


@dataclass
class History:
    """Time histories at every step (floors 1..3 in columns)."""

    t: np.ndarray
    floors: np.ndarray
    floor_velocities: np.ndarray
    floor_accelerations: np.ndarray
    phi: np.ndarray
    phi_rate: np.ndarray
    excitation: np.ndarray
    energy: np.ndarray
    meta: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {
            "peak_displacement_m": np.max(np.abs(self.floors), axis=0).tolist(),
            "peak_acceleration_m_s2": np.max(np.abs(self.floor_accelerations), axis=0).tolist(),
            "peak_phi_rad": float(np.max(np.abs(self.phi))),
            "final_energy_j": float(self.energy[-1]),
            **self.meta,
        }


class _Recorder:
    def __init__(self, system: MechanicalSystem, n_samples: int) -> None:
        self.system = system
        model = system.model
        self.fi, self.pi, self.nd = model.floor_index, model.phi_index, model.n_dof
        self.rows = np.empty((n_samples, 14))

    def __call__(self, k: int, t: float, x: np.ndarray) -> None:
        q, v = x[: self.nd], x[self.nd :]
        a = self.system.derivative(t, x)[self.nd :]
        load = self.system.load(t)[:3].sum() if self.system.load else 0.0
        self.rows[k] = (t, *q[self.fi], *v[self.fi], *a[self.fi], q[self.pi], v[self.pi], load,
                        self.system.energy(x))

    def history(self, meta: dict) -> History:
        r = self.rows
        return History(r[:, 0], r[:, 1:4], r[:, 4:7], r[:, 7:10], r[:, 10], r[:, 11], r[:, 12],
                       r[:, 13], meta)


def simulate(scene: Scene, duration: float | None = None,
             progress: Progress | None = None) -> History:
    """Integrate the scene open loop and record floor motion, φ, the load and the energy. One
    structure: a scene with ``events`` is refused (the loop's plant applies them)."""
    if scene.events:
        raise InputError("events: simulate integrates one structure; the loop's plant applies "
                         "structure events (stillframe closed-loop, launch)")
    duration = scene.duration if duration is None else duration
    if scene.model.type == "ph":
        return _ph_history(scene, duration, progress)
    model = build_model(scene)
    system = MechanicalSystem(model, floor_load(scene.excitation, duration))
    x0 = initial_state(model, scene.initial)
    dt = scene.integrator.dt
    n_steps = max(1, round(duration / dt))
    recorder = _Recorder(system, n_steps + 1)
    method = scene.integrator.method
    compiled = compiles(system.load, method)  # False for the adaptive methods
    if method == "rk4":
        check_rk4_step(model, dt)
    start = time.perf_counter()
    subdivisions = 0
    if method in ADAPTIVE:
        t_eval = np.arange(n_steps + 1) * dt
        states = reference_solution(system, x0, t_eval, method, scene.integrator.rtol,
                                    scene.integrator.atol)
        for k, (t, x) in enumerate(zip(t_eval, states, strict=True)):
            recorder(k, t, x)
    else:
        every = max(1, n_steps // 100)

        def observe(k: int, t: float, x: np.ndarray) -> None:
            recorder(k, t, x)
            if progress and k % every == 0:
                progress(k / n_steps)

        subdivision = Subdivision.of(scene.integrator)
        if compiled:
            subdivisions = compiled_integrate(model, system.load, method, x0, dt, n_steps,
                                              observer=observe, subdivision=subdivision)
        else:
            integrator = make_integrator(method, subdivision)
            integrate(system, x0, dt, n_steps, integrator, observer=observe)
            subdivisions = integrator.subdivisions
    wall = time.perf_counter() - start
    meta = {"model": model.name, "dofs": model.n_dof, "integrator": method, "dt": dt,
            "compiled": compiled,
            "steps": n_steps, "subdivisions": subdivisions, "wall_s": wall,
            "steps_per_s": n_steps / wall}
    history = recorder.history(meta)
    warning = drift_warning(model, history.floors, scene.rig.columns.lengths)
    if warning:
        log.warning("%s: %s", scene.name, warning)
        meta["warnings"] = [warning]
    return history


def _ph_history(scene: Scene, duration: float, progress: Progress | None) -> History:
    """``model.type: ph``: the frame pHDAE (:mod:`stillframe.dynamics.ph.scene_model`)."""
    start = time.perf_counter()
    run = ph_scene.simulate(scene, duration, progress)
    wall = time.perf_counter() - start
    meta = {**run.pop("meta"), "compiled": True, "wall_s": wall}
    meta["steps_per_s"] = meta["steps"] / wall
    return History(**run, meta=meta)
