"""The frame pHDAE's compiled step (``frame_step``) against the generic pHDAE integrator, the
index-1 reference and the FE model; damping and process noise as the FE plant takes them."""

import numpy as np
import pytest

from stillframe.config.scene import load_scene
from stillframe.dynamics.modal_analysis import modal_table as fe_modal_table
from stillframe.dynamics.models import build_model
from stillframe.dynamics.ph import scene_model
from stillframe.dynamics.ph.integrator import MidpointDAE
from stillframe.dynamics.ph.reference import index1_rhs
from stillframe.errors import InputError
from stillframe.plant.frame_plant import make_plant
from tests.support.middleware import run_stillframe

SWING = ["model.type=ph", "model.elements_per_column=3", "initial.phi=0.5",
         "initial.floors=[0.002, 0.004, 0.005]", "initial.phi_rate=1.0"]
CONTROL = np.array([0.0, 0.0, 0.05, 0.01])


def force(t):
    return 0.1 * np.sin(7.0 * t)


def frame_and_state(overrides):
    scene = load_scene("scenes/thesis_fe.yaml", SWING + overrides)
    fs = scene_model.scene_frame(scene)
    return fs, scene_model.initial_state(fs.system, scene)


def test_compiled_step_is_the_generic_phdae_midpoint_step():
    fs, e0 = frame_and_state([])
    h, steps = 1e-3, 40
    dae = MidpointDAE(fs.system, h, lambda t: np.array([force(t), 0.0, 0.0, 0.0]) + CONTROL)
    e, lam = e0.copy(), np.zeros(fs.system.n_constraints)
    for k in range(steps):
        e, lam = dae.step(e, lam, k * h)
    stepper = fs.stepper(h)
    z = stepper.reduce(e0)
    loads = np.zeros((steps, 3))
    loads[:, 0] = force((np.arange(steps) + 0.5) * h)
    stepper.run(z, loads, CONTROL, np.zeros(4))
    # the same discrete solution (MidpointDAE: dense Newton on all 150 unknowns)
    difference = stepper.expand(z) - e
    assert np.max(np.abs(difference)) < 1e-8
    # the same H: the energies differ by what the states' difference moves it, |∇H|·|Δe| to
    # first order (∇H = Eᵀz), plus the two evaluations' round-off, a few u·H
    gradient = fs.system.descriptor.T @ fs.system.z(e)
    bound = 2 * np.abs(gradient) @ np.abs(difference) + 1e-14 * abs(fs.system.hamiltonian(e))
    assert abs(stepper.energy(z) - stepper.energy(stepper.reduce(e))) < bound


def test_discrete_power_balance_per_step_holds_to_round_off_with_every_port():
    fs, e0 = frame_and_state(["damping.model=modal"])
    stepper = fs.stepper(1e-3)
    z = stepper.reduce(e0)
    steps = 300
    loads = np.zeros((steps, 3))
    loads[:, 0] = force((np.arange(steps) + 0.5) * 1e-3)
    states = np.empty((steps + 1, z.size))
    states[0] = z
    _, energy = stepper.run(z, loads, CONTROL, np.array([0.2, -0.1, 0.3, 0.02]),
                            states=states[1:])
    change = stepper.energy_changes(states)
    residual = change - energy[:, :3].sum(axis=1) + energy[:, 3]
    scale = np.max(stepper.energies(states))
    assert np.max(np.abs(residual)) < 1e-14 * scale
    assert np.all(energy[:, 3] >= 0) and np.all(np.abs(energy[:, :3]) > 0)


def test_floor_accelerations_equal_the_index1_form():
    fs, e0 = frame_and_state(["damping.model=modal"])
    u = np.array([0.3, 0.1, 0.2, 0.05])
    stepper = fs.stepper(1e-3)
    rates = index1_rhs(fs.system, lambda t: u)(0.0, e0)[fs.system.n_q:]
    expected = [rates[fs.system.q_slices[f"floor{i}"].start] for i in (1, 2, 3)]
    # the reference differentiates the constraints by central differences (step 1e-7)
    np.testing.assert_allclose(stepper.floor_accelerations(stepper.reduce(e0), u), expected,
                               atol=1e-7 * np.max(np.abs(expected)))


@pytest.mark.parametrize("damping", [["damping.model=modal"],
                                     ["damping.model=rayleigh", "damping.beta=1e-4"]])
def test_damping_ratios_equal_the_fe_models(damping):
    ph = scene_model.modal_table(load_scene("scenes/thesis_fe.yaml",
                                            ["model.type=ph", *damping]))
    fe = modal_table(load_scene("scenes/thesis_fe.yaml", damping))
    np.testing.assert_allclose(ph["frequencies_hz"][:9], fe["frequencies_hz"][:9], rtol=1e-6)
    np.testing.assert_allclose(ph["damping_ratios"][:9], fe["damping_ratios"][:9], rtol=1e-5)


def test_negative_beta_is_judged_per_mode_like_the_fe_model():
    hammer = ["model.elements_per_column=3"]
    messages = []
    for model in ("fe", "ph"):
        with pytest.raises(InputError, match=r"^damping\.beta: .* mode 4 at 69\.2 Hz") as err:
            scene_model.modal_table(load_scene("scenes/hammer_test.yaml",
                                               [f"model.type={model}", *hammer])) \
                if model == "ph" else modal_table(load_scene("scenes/hammer_test.yaml",
                                                             [f"model.type={model}", *hammer]))
        messages.append(str(err.value).replace(f"{model}3", "MODEL"))
    assert messages[0] == messages[1]
    # one element per column: three structural modes, all below 9.3 Hz, accepted by both
    one = ["model.elements_per_column=1"]
    ph = scene_model.modal_table(load_scene("scenes/hammer_test.yaml", ["model.type=ph", *one]))
    fe = modal_table(load_scene("scenes/hammer_test.yaml", ["model.type=fe", *one]))
    np.testing.assert_allclose(ph["damping_ratios"][:4], fe["damping_ratios"][:4], rtol=1e-6)


def modal_table(scene):
    return fe_modal_table(build_model(scene))


def lqg_on_ph(extra):
    return load_scene("scenes/thesis_lqg.yaml", ["model.type=ph", "plant.model=scene",
                                                 "damping.model=modal", *extra])


def test_process_noise_enters_through_the_force_ports_from_the_fe_plants_stream():
    scene = lqg_on_ph([])
    plant = make_plant(scene)
    draws = np.random.default_rng(scene.plant.seed).standard_normal(8)
    std = np.asarray(scene.plant.process_noise_std)
    p = scene.rig.pendulum
    inertia = np.array([*scene.rig.floor_masses, p.inertia + p.mass * p.half_length**2])
    T = plant.period
    held, doublet = inertia * std[4:] * draws[4:] / T, 4 * inertia * std[:4] * draws[:4] / T**2
    H0 = plant.stepper.energy(plant.z)
    plant.advance(np.zeros(2))
    np.testing.assert_allclose(plant.noise, held - doublet, rtol=1e-15)  # second half
    t, balance = plant.energy_sample()
    stored, exc, act, noise, lost = balance
    assert t == T and noise != 0.0 and lost > 0
    # the period's balance: ΔH = T (P_exc + P_act + P_noise − P_diss)
    assert abs(stored - H0 - T * (exc + act + noise - lost)) < 1e-13 * max(stored, H0)


def test_free_mass_gets_the_fe_plants_jump_from_the_noise_forces():
    """The noise force schedule on an isolated mass m: held w_v over T and ±w_x over the halves
    give Δv = σ_v ξ_v and Δx = σ_x ξ_x + σ_v ξ_v T/2 (closed form, exact for a free mass)."""
    m, T, sv, sx = 2.0, 0.03125, 1e-3, 2e-3
    wv, wx = m * sv / T, 4 * m * sx / T**2
    # piecewise-constant force: exact kinematics
    v1 = (wv + wx) * T / 2 / m
    x1 = 0.5 * (wv + wx) / m * (T / 2) ** 2
    v2 = v1 + (wv - wx) * T / 2 / m
    x2 = x1 + v1 * T / 2 + 0.5 * (wv - wx) / m * (T / 2) ** 2
    assert v2 == pytest.approx(sv)
    assert x2 == pytest.approx(sx + sv * T / 2)


def test_displacement_noise_needs_an_even_step_count_one_line_exit_2():
    done = run_stillframe("closed-loop", "scenes/thesis_lqg.yaml", "--set", "model.type=ph",
                          "--set", "plant.model=scene", "--set", "damping.model=modal",
                          "--set", "integrator.dt=0.0104166666666666667", timeout=120)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "plant.process_noise_std" in lines[0]
