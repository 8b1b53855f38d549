"""``model.type: ph`` scenes: the frame pHDAE built, analysed and integrated from a scene.

Damping: the scene's ``damping`` section applied as the FE model applies it
(:func:`stillframe.dynamics.models.damping.damping_parts_of`), to the structure in the null
space of its constraints (M̂, K̂ of :mod:`stillframe.dynamics.ph.frame_step`): ``rayleigh``
R̂ = αM̂ + βK̂ (β < 0 accepted while every structural mode keeps a damping ratio ≥ 0, else the
FE model's one-line error naming ``damping.beta``), ``modal`` (the same ratios on the same modes,
R̂ = β_h K̂ + Σ (2ζ_jω_j − β_hω_j²) M̂φ_jφ_jᵀM̂) or ``none``; in every case R = P R̂ Pᵀ ⪰ 0 on the
structural velocities, plus the hinge damper r4. Integration: the AVF implicit midpoint rule at
``integrator.dt`` whatever ``integrator.method`` says, compiled
(:class:`~stillframe.dynamics.ph.frame_step.CompiledFramePH`: the same step as
:class:`~stillframe.dynamics.ph.integrator.MidpointDAE`). Initial floors are displaced with the
columns in static equilibrium; initial velocities are the M-nearest consistent ones to the given
floor velocities and φ̇.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from stillframe.config.scene import Scene
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.models.damping import damping_parts_of
from stillframe.dynamics.ph import frame
from stillframe.dynamics.ph.frame_step import CompiledFramePH, frame_reduction
from stillframe.dynamics.ph.linear import natural_frequencies, reduced_matrices
from stillframe.dynamics.ph.system import PHSystem, VelocityDamping

#: steps per call of the compiled kernel in :func:`simulate`
CHUNK = 4096


@dataclass(frozen=True)
class FrameScene:
    """A scene's frame pHDAE: the system (structural damping included), its rest configuration
    and the structural damping R̂ in the reduced coordinates."""

    system: PHSystem
    q_rest: np.ndarray
    damping: np.ndarray

    def stepper(self, h: float) -> CompiledFramePH:
        return CompiledFramePH(self.system, self.q_rest, h, self.damping)


def scene_frame(scene: Scene) -> FrameScene:
    elements = scene.model.elements_per_column
    system = frame.frame_system(scene.rig, elements)
    q_rest = frame.rest_configuration(system, scene.rig)
    red = frame_reduction(system, q_rest)
    parts = damping_parts_of(red.mass, red.stiffness, scene.damping, f"ph{elements}")
    damping = parts.matrix(red.mass, red.stiffness)
    damping = 0.5 * (damping + damping.T)
    if np.any(damping):
        system.dampers.append(VelocityDamping(red.structural, red.P @ damping @ red.P.T))
    return FrameScene(system, q_rest, damping)


def scene_system(scene: Scene) -> PHSystem:
    return scene_frame(scene).system


def modal_table(scene: Scene) -> dict:
    """Frequencies, damping ratios and shapes (floors, φ; normalised to floor 1) at rest, in the
    format of :func:`stillframe.dynamics.modal_analysis.modal_table`."""
    fs = scene_frame(scene)
    system, q = fs.system, fs.q_rest
    omega, modes = natural_frequencies(system, q)
    A = system.kinematics(q)
    picks = [system.q_slices[f"floor{i}"].start for i in (1, 2, 3)]
    picks.append(system.q_slices["pendulum"].start + 2)
    rows = (A @ modes)[picks]
    P, M, C, K = reduced_matrices(system, q)
    n = M.shape[0]
    first_order = np.block([[np.zeros((n, n)), np.eye(n)],
                            [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam = np.linalg.eigvals(first_order)
    lam = lam[lam.imag > 1e-9]
    lam = lam[np.argsort(np.abs(lam))]
    zeta = (-lam.real / np.abs(lam))[:omega.size]
    return {"model": f"ph{scene.model.elements_per_column}", "dofs": int(P.shape[1]),
            "frequencies_hz": (omega / (2 * np.pi)).tolist(),
            "damping_ratios": np.pad(zeta, (0, omega.size - zeta.size)).tolist(),
            "mode_shapes": (rows / rows[0]).T.tolist()}


def initial_state(system: PHSystem, scene: Scene) -> np.ndarray:
    init = scene.initial
    q = frame.rest_configuration(system, scene.rig, np.asarray(init.floors), init.phi)
    guess = np.zeros(system.n_q)
    for i, v in enumerate(init.floor_velocities, start=1):
        guess[system.q_slices[f"floor{i}"].start] = v
    guess[system.q_slices["pendulum"].start + 2] = init.phi_rate
    nu = system.consistent_velocity(q, guess)
    return system.state(q, nu, frame.static_stresses(system, q))


def simulate(scene: Scene, duration: float,
             progress: Callable[[float], None] | None = None) -> dict:
    """Time histories (floors, velocities, accelerations, φ, φ̇, load, energy above rest) and the
    run's largest relative discrete power-balance residual (one step at a time)."""
    fs = scene_frame(scene)
    system = fs.system
    load = floor_load(scene.excitation, duration)
    dt = scene.integrator.dt
    steps = max(1, round(duration / dt))
    stepper = fs.stepper(dt)
    z = stepper.reduce(initial_state(system, scene))
    mids = (np.arange(steps) + 0.5) * dt
    loads = np.zeros((steps, 3))
    if load is not None:
        loads[:, load.excitation.floor - 1] = load.force_at(mids)
    states = np.empty((steps + 1, z.size))
    states[0] = z
    supplied = np.empty(steps)
    dissipated = np.empty(steps)
    zero = np.zeros(4)
    for start in range(0, steps, CHUNK):
        stop = min(steps, start + CHUNK)
        _, energy = stepper.run(z, loads[start:stop], zero, zero, t0=start * dt,
                                states=states[start + 1:stop + 1])
        supplied[start:stop] = energy[:, :3].sum(axis=1)
        dissipated[start:stop] = energy[:, 3]
        if progress is not None:
            progress(stop / steps)
    times = np.arange(steps + 1) * dt
    energy = stepper.energies(states)
    readings = stepper.readings(states)
    residual = stepper.energy_changes(states) - supplied + dissipated
    scale = float(np.max(np.abs(energy))) or 1.0
    velocities = readings["floor_velocities"]
    excitation = np.zeros(times.size) if load is None else load.force_at(times)
    return {
        "t": times, "floors": readings["floors"], "floor_velocities": velocities,
        "floor_accelerations": np.gradient(velocities, times, axis=0),
        "phi": readings["phi"], "phi_rate": readings["phi_rate"],
        "excitation": excitation,
        "energy": energy,
        "meta": {"model": f"ph{scene.model.elements_per_column}", "dofs": system.n,
                 "integrator": "midpoint (AVF, pHDAE, compiled)", "dt": dt, "steps": steps,
                 "energy_balance_error": float(np.max(np.abs(residual)) / scale),
                 "max_constraint_drift": float(max(
                     _drift(system, stepper.expand(states[i])) for i in (0, steps)))},
    }


def _drift(system: PHSystem, e: np.ndarray) -> float:
    g = system.constraints(system.split(e)[0], 0.0)[0]
    return float(np.max(np.abs(g))) if g.size else 0.0
