"""The frame and pendulum as a pHDAE against the FE model, and its energy behaviour."""

import json

import numpy as np
import pytest
import scipy.linalg as sla

from stillframe.config.scene import load_scene
from stillframe.dynamics.models import build_model
from stillframe.dynamics.ph import frame
from stillframe.dynamics.ph.integrator import NEWTON_TOL, MidpointDAE, balance_error
from stillframe.dynamics.ph.linear import natural_frequencies

FE40_HZ = np.array([1.0995, 1.9115, 5.5743, 8.4802])  # README: FE model, 40 el./column


@pytest.fixture(scope="module")
def scene():
    return load_scene("scenes/thesis_fe.yaml")


def fe_frequencies(elements: int) -> np.ndarray:
    lin = build_model(load_scene("scenes/thesis_fe.yaml",
                                 [f"model.elements_per_column={elements}"])).linearized()
    w2 = sla.eigh(lin.stiffness, lin.mass, eigvals_only=True)
    return np.sqrt(w2) / (2 * np.pi)


def test_frequencies_equal_the_fe_model_on_the_same_mesh_and_converge_to_its_40_element_values(
        scene):
    system = frame.frame_system(scene.rig, 3)
    q = frame.rest_configuration(system, scene.rig)
    ph = natural_frequencies(system, q, 6)[0] / (2 * np.pi)
    # same assumptions except extensible columns: equal to 1e-6 on the same mesh
    np.testing.assert_allclose(ph, fe_frequencies(3)[:6], rtol=1e-6)
    np.testing.assert_allclose(ph[:4], FE40_HZ, atol=5e-5)


def released(scene, rayleigh=None):
    """Floors displaced 5/10/15 mm with the columns in static equilibrium, pendulum at 0.3 rad."""
    system = frame.frame_system(scene.rig, 2, rayleigh)
    q = frame.rest_configuration(system, scene.rig, np.array([0.005, 0.010, 0.015]), phi=0.3)
    return system, system.state(q, stress=frame.static_stresses(system, q))


@pytest.mark.slow
def test_undamped_frame_conserves_h_and_a_damped_one_dissipates_exactly_z_r_z(scene):
    """Each step balances to below NEWTON_TOL·H (Newton's stop rule: the AVF balance is exact at
    the step's solution, see test_ph_integrator), so 100 steps keep H and the dissipated sum to
    100·NEWTON_TOL·H, ≈ 1e-9 of the energy the damped run loses. The drift (m) adds per step the
    rounding of q (u·|q| ≲ 1e-15) and h times the velocity constraint's Newton residual."""
    scene_u = load_scene("scenes/thesis_fe.yaml", ["rig.pendulum.hinge_damping=0"])
    system, e0 = released(scene_u)
    _, states, record, drift = MidpointDAE(system, 2e-3).run(e0, 0.2)
    H = np.array([system.hamiltonian(e) for e in states])
    steps = len(record.delta_h)
    assert np.max(np.abs(H - H[0])) < steps * NEWTON_TOL * abs(H[0])
    assert drift.max() < 1e-12
    system, e0 = released(scene, rayleigh=(0.5, 1e-4))
    _, states, record, _ = MidpointDAE(system, 2e-3).run(e0, 0.2)
    H = np.array([system.hamiltonian(e) for e in states])
    lost = H[0] - H[-1]
    assert lost > 1e-3  # J: the columns' and floors' Rayleigh R and the hinge damper work
    assert abs(lost - np.sum(record.dissipated)) < steps * NEWTON_TOL * abs(H[0])
    assert balance_error(record, abs(H[0])) < NEWTON_TOL


def test_modes_command_runs_the_ph_scene(capsys):
    from stillframe.app.cli import main
    assert main(["modes", "scenes/ph_frame.yaml", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["model"] == "ph2"
    np.testing.assert_allclose(doc["frequencies_hz"][:6], fe_frequencies(2)[:6], rtol=1e-6)


@pytest.mark.slow
def test_simulate_json_reports_the_power_balance_and_follows_the_fe_model(capsys):
    from stillframe.app.cli import main
    from stillframe.dynamics.simulation import simulate
    assert main(["simulate", "scenes/ph_frame.yaml", "--duration", "0.3", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["energy_balance_error"] < 1e-13
    fe = simulate(load_scene("scenes/ph_frame.yaml", ["model.type=fe"]), 0.3).summary()
    np.testing.assert_allclose(doc["peak_displacement_m"], fe["peak_displacement_m"], rtol=2e-3)
    assert abs(doc["peak_phi_rad"] - fe["peak_phi_rad"]) < 2e-3 * fe["peak_phi_rad"]


def test_tools_built_on_frame_models_reject_ph_with_a_clear_error():
    from stillframe.errors import InputError
    with pytest.raises(InputError, match=r"model\.type: ph"):
        build_model(load_scene("scenes/ph_frame.yaml"))
