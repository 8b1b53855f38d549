"""Stability at the extremes (docs/extremes.md): each row works within a stated accuracy or fails
early with a clear error or warning."""

from __future__ import annotations

import logging
import re

import numpy as np
import pytest
import scipy.linalg as sla

from stillframe.config.scene import scene_from_dict
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.integrators import NO_SUBDIVISION, reference_solution
from stillframe.dynamics.kernels import CompiledFrame
from stillframe.dynamics.models import build_model, build_structure
from stillframe.dynamics.models.damping import undamped_modes
from stillframe.dynamics.simulation import initial_state, simulate
from stillframe.dynamics.stability import RK4_IMAGINARY_LIMIT, rk4_growth, rk4_stable_step
from stillframe.dynamics.systems import MechanicalSystem
from stillframe.errors import InputError, IntegrationError

UNDAMPED = ["damping.model=none", "rig.pendulum.hinge_damping=0"]


def _setup(overrides: list[str]):
    scene = scene_from_dict({"name": "t"}, overrides)
    model = build_model(scene)
    return scene, model, CompiledFrame(model), initial_state(model, scene.initial)


# --- step size up to the explicit stability limit ------------------------------------------------
def _grows(frame: CompiledFrame, x0: np.ndarray, h: float, steps: int = 20_000) -> bool:
    try:
        states = frame.run("rk4", x0, h, steps, stride=steps // 10)
    except IntegrationError:
        return True
    return bool(np.max(np.abs(states[-1])) > 10 * np.max(np.abs(x0)))


@pytest.mark.parametrize("overrides", [
    ["initial.floors=[1e-4, -1e-4, 1e-4]", *UNDAMPED],
    ["model.type=fe", "model.elements_per_column=2", "damping.model=modal",
     "initial.floors=[1e-4, -1e-4, 1e-4]"],
])
def test_rk4_blows_up_just_beyond_the_predicted_limit_and_not_just_below(overrides) -> None:
    _, model, subdivided, x0 = _setup(overrides)
    frame = CompiledFrame(model, NO_SUBDIVISION)  # the bare method
    x0[model.n_dof:] = 1e-3  # excite every mode, the fastest included
    limit = rk4_stable_step(model)
    assert not _grows(frame, x0, 0.99 * limit)
    assert _grows(frame, x0, 1.01 * limit)
    # with the error estimate (the default) the steps beyond the limit are halved where needed:
    # the energy of the free (passive) model never grows, as it does for the bare method
    states = subdivided.run("rk4", x0, 1.01 * limit, 2000, stride=100)
    energy = [model.energy(x[:model.n_dof], x[model.n_dof:]) for x in states]
    assert np.all(np.isfinite(states)) and max(energy) <= energy[0] * (1 + 1e-9)
    assert subdivided.subdivisions > 0
    if "damping.model=none" in overrides:
        # undamped: the limit is the imaginary-axis bound h ω_max = 2√2 (closed form)
        omega_max = np.max(np.abs(np.linalg.eigvals(model.linearized().state_space()[0])))
        assert limit * omega_max == pytest.approx(RK4_IMAGINARY_LIMIT, rel=1e-6)


def test_simulate_refuses_an_rk4_step_beyond_the_limit_before_integrating() -> None:
    scene = scene_from_dict({"name": "t"}, ["model.type=fe", "damping.model=modal",
                                            "integrator.method=rk4", "integrator.dt=1e-3"])
    with pytest.raises(InputError, match=r"integrator\.dt: 0\.001 s is beyond RK4's stability "
                                         r"limit 0\.000361 s for the fe3 model"):
        simulate(scene, duration=1.0)


# --- fine meshes ---------------------------------------------------------------------------------
def test_fine_meshes_up_to_200_elements_stiffen_as_n_squared_and_stay_accurate() -> None:
    meshes = [10, 25, 50, 100, 200]
    top = []
    for n in meshes:
        s = scene_from_dict({"name": "t"}, ["model.type=fe", f"model.elements_per_column={n}",
                                            "damping.model=modal"])
        structure = build_structure(s)
        # the direct problem is the accurate one for the highest mode (low_modes_first's docstring)
        top.append(np.sqrt(sla.eigh(structure.stiffness, structure.mass, eigvals_only=True)[-1]))
    # the highest FE frequency of a beam grows as 1/le² = n² (so cond(K) ∝ n⁴)
    assert np.polyfit(np.log(meshes), np.log(top), 1)[0] == pytest.approx(2.0, abs=0.02)
    # the modal damping puts ζ₁₋₃ on the true modes even at FE 200 (cond M 3.5e11): measured to
    # 2.5e-10; shapes from eigh(K, M) gave ζ₁ 0.03956 there, and the floors below differed by 2.7e-4
    omega, phi = undamped_modes(structure)
    damping = build_model(s).c_struct
    zeta = np.einsum("ij,ik,kj->j", phi[:, :3], damping, phi[:, :3]) / (2 * omega[:3])
    np.testing.assert_allclose(zeta, [0.0395, 0.0030, 0.0042], rtol=1e-8)
    # FE 200 (1198 DOFs), implicit midpoint at 1 ms agrees with FE 40 on the floors: measured
    # 1.9e-8 (FE 100: 1.5e-9); the same at 0.25 ms, so it is the model, not the time step
    runs = {}
    for n in (40, 200):
        scene, _, frame, x0 = _setup([
            "model.type=fe", f"model.elements_per_column={n}", "damping.model=modal",
            "excitation.type=harmonics"])
        states = frame.run("midpoint", x0, 1e-3, 2000, load=floor_load(scene.excitation, 2.0),
                           stride=10)
        runs[n] = states[:, :3]
    error = np.max(np.abs(runs[200] - runs[40])) / np.max(np.abs(runs[40]))
    assert error < 1e-6, error


# --- long undamped runs --------------------------------------------------------------------------
def test_energy_drift_over_a_million_steps_matches_rk4_damping_and_midpoint_stays_bounded(
) -> None:
    """Undamped lumped model, 1e6 steps of 1 ms. RK4 loses the energy of mode j as
    |R(i ω_j h)|^(2N) (closed form on the linearised modes); midpoint keeps it bounded."""
    _, model, frame, x0 = _setup([*UNDAMPED, "initial.floors=[1e-5, 2e-5, 3e-5]"])
    h, n = 1e-3, 1_000_000
    lin = model.linearized()
    w2, phi = sla.eigh(lin.stiffness, lin.mass)
    q0, v0 = x0[:model.n_dof], x0[model.n_dof:]
    modal_energy = 0.5 * w2 * (phi.T @ lin.mass @ q0) ** 2 + 0.5 * (phi.T @ lin.mass @ v0) ** 2
    factor = rk4_growth(1j * np.sqrt(w2) * h) ** (2 * n)
    predicted = float(modal_energy @ factor / modal_energy.sum())
    e0 = model.energy(q0, v0)
    drift = {}
    for method in ("rk4", "midpoint"):
        states = frame.run(method, x0, h, n, stride=10_000)
        energy = np.array([model.energy(x[:model.n_dof], x[model.n_dof:]) for x in states])
        drift[method] = energy / e0
    assert 1 - predicted > 1e-5  # a measurable loss
    assert drift["rk4"][-1] == pytest.approx(predicted, rel=1e-6)
    assert np.max(np.abs(drift["midpoint"] - 1)) < 1e-9


# --- large motion --------------------------------------------------------------------------------
def test_pendulum_full_rotations_agree_with_the_adaptive_reference() -> None:
    """φ̇(0) = 20 rad/s carries the pendulum over the top (needs 13.9 rad/s) several times."""
    _, model, frame, x0 = _setup([*UNDAMPED, "initial.phi_rate=20"])
    states = frame.run("midpoint", x0, 1e-4, 20_000, stride=100)
    system = MechanicalSystem(model)
    t = np.arange(0, 201) * 1e-2
    exact = reference_solution(system, x0, t, "dop853", 1e-12, 1e-14)
    assert exact[-1, model.phi_index] > 4 * np.pi  # at least two full turns
    assert np.max(np.abs(states[:, model.phi_index] - exact[:, model.phi_index])) < 1e-3
    floors = np.max(np.abs(states[:, :3] - exact[:, :3])) / np.max(np.abs(exact[:, :3]))
    assert floors < 1e-3
    e0 = system.energy(x0)
    energy = [system.energy(x) for x in states]
    assert np.max(np.abs(np.array(energy) / e0 - 1)) < 1e-4


def test_large_floor_amplitudes_warn_that_the_columns_leave_linear_theory(caplog) -> None:
    small = simulate(scene_from_dict({"name": "t"}, ["initial.floors=[0.001, 0.002, 0.003]",
                                                     "duration=0.2"]))
    assert "warnings" not in small.meta
    with caplog.at_level(logging.WARNING, logger="stillframe.dynamics.simulation"):
        large = simulate(scene_from_dict({"name": "t"}, ["initial.floors=[0.05, 0.1, 0.15]",
                                                         "duration=0.2"]))
    assert re.match(r"story \d drifts \d+\.\d% of its height \(> 2%\)", large.meta["warnings"][0])
    assert "outside the linear column theory" in caplog.text
    # the linear structure still scales exactly: 50x the amplitude, 50x the floor motion
    # (the pendulum is a small nonlinear load at these amplitudes)
    ratio = np.max(np.abs(large.floors), axis=0) / np.max(np.abs(small.floors), axis=0)
    np.testing.assert_allclose(ratio, 50, rtol=5e-3)
