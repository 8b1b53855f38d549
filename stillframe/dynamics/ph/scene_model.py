"""``model.type: ph`` scenes: the frame pHDAE built, analysed and integrated from a scene.

Damping: ``damping.model: none``, or ``rayleigh`` with α, β ≥ 0 (R = αM + βDᵀC⁻¹D must be
⪰ 0; the thesis's identified β < 0 is not), always with the hinge damper r4. Integration: the
AVF implicit midpoint rule (:mod:`stillframe.dynamics.ph.integrator`) at ``integrator.dt`` whatever
``integrator.method`` says. Initial floors are displaced with the columns in static equilibrium;
initial velocities are the M-nearest consistent ones to the given floor velocities and φ̇.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from stillframe.config.scene import Scene
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.ph import frame
from stillframe.dynamics.ph.integrator import MidpointDAE, balance_error
from stillframe.dynamics.ph.linear import natural_frequencies, reduced_matrices
from stillframe.dynamics.ph.system import PHSystem
from stillframe.errors import InputError


def scene_system(scene: Scene) -> PHSystem:
    d = scene.damping
    if d.model == "modal":
        raise InputError("damping.model: model.type ph takes rayleigh (alpha, beta >= 0) or none")
    rayleigh = (d.alpha, d.beta) if d.model == "rayleigh" else None
    return frame.frame_system(scene.rig, scene.model.elements_per_column, rayleigh)


def modal_table(scene: Scene) -> dict:
    """Frequencies, damping ratios and shapes (floors, φ; normalised to floor 1) at rest, in the
    format of :func:`stillframe.dynamics.modal_analysis.modal_table`."""
    system = scene_system(scene)
    q = frame.rest_configuration(system, scene.rig)
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
    run's largest relative discrete power-balance residual."""
    system = scene_system(scene)
    load = floor_load(scene.excitation, duration)
    dt = scene.integrator.dt
    steps = max(1, round(duration / dt))

    def inputs(t: float) -> np.ndarray:
        return np.concatenate([load(t) if load is not None else np.zeros(3), [0.0]])

    e0 = initial_state(system, scene)
    integrator = MidpointDAE(system, dt, inputs)
    report = None if progress is None else (lambda t: progress(t / duration))
    times, states, record, drift = integrator.run(e0, steps * dt, progress=report)
    readings = [frame.sensors(system, e) for e in states]
    rest = system.hamiltonian(system.state(frame.rest_configuration(system, scene.rig)))
    energy = np.array([system.hamiltonian(e) for e in states]) - rest
    velocities = np.array([r["floor_velocities"] for r in readings])
    return {
        "t": times, "floors": np.array([r["floors"] for r in readings]),
        "floor_velocities": velocities,
        "floor_accelerations": np.gradient(velocities, times, axis=0),
        "phi": np.array([r["phi"] for r in readings]),
        "phi_rate": np.array([r["phi_rate"] for r in readings]),
        "excitation": np.array([inputs(t)[:3].sum() for t in times]),
        "energy": energy,
        "meta": {"model": f"ph{scene.model.elements_per_column}", "dofs": system.n,
                 "integrator": "midpoint (AVF, pHDAE)", "dt": dt, "steps": steps,
                 "energy_balance_error": balance_error(record, float(np.max(np.abs(energy)))
                                                       or 1.0),
                 "max_constraint_drift": float(drift.max())},
    }
