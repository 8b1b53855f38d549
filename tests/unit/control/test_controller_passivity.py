"""The passivity-based controller: stable on every plant model with the same gains."""

import numpy as np
import pytest
import scipy.linalg as sla

from stillframe.config.scene import load_scene
from stillframe.control.factory import make_controller
from stillframe.control.passivity import PassivityLaw
from stillframe.dynamics.models import build_model
from stillframe.dynamics.ph import frame
from stillframe.dynamics.ph.linear import reduced_matrices
from stillframe.dynamics.ph.scene_model import scene_system
from stillframe.errors import InputError

GAINS = [(0.0, 0.05), (0.5, 0.05), (5.0, 2.0)]  # (k_p, k_d), never retuned per plant


def frame_abscissa(overrides, kp, kd):
    """Largest real part of the linearised closed loop of a FrameModel plant."""
    model = build_model(load_scene("scenes/thesis_fe.yaml", overrides))
    A, B = model.linearized().state_space()
    n = model.n_dof
    law = PassivityLaw(n, model.phi_index, kp, kd)
    gain = np.zeros(2 * n)
    gain[law.angle], gain[law.rate] = kp, kd
    return np.max(np.linalg.eigvals(A - np.outer(B[:, 3], gain)).real)


def ph_abscissa(kp, kd):
    scene = load_scene("scenes/ph_frame.yaml")
    system = scene_system(scene)
    q = frame.rest_configuration(system, scene.rig)
    P, M, C, K = reduced_matrices(system, q)
    # the pendulum angle rate in reduced coordinates: c ξ̇ = φ̇
    c = (system.kinematics(q) @ P)[system.q_slices["pendulum"].start + 2]
    K, C = K + kp * np.outer(c, c), C + kd * np.outer(c, c)
    n = M.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)],
                  [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    return np.max(np.linalg.eigvals(A).real)


@pytest.mark.parametrize(("kp", "kd"), GAINS)
def test_closed_loop_is_stable_on_every_plant_model_with_the_same_gains(kp, kd):
    for overrides in (["model.type=lumped", "damping.model=rayleigh"], ["model.type=fe"],
                      ["model.type=modal", "model.modes=3"]):
        assert frame_abscissa(overrides, kp, kd) < -1e-3, overrides
    assert ph_abscissa(kp, kd) < -1e-3


def test_injection_damps_the_pendulum_more_than_the_open_loop():
    open_loop = frame_abscissa(["model.type=lumped", "damping.model=rayleigh"], 0.0, 1e-12)
    closed = frame_abscissa(["model.type=lumped", "damping.model=rayleigh"], 0.0, 0.05)
    assert closed < open_loop


def test_negative_gains_are_rejected():
    with pytest.raises(InputError, match="passivity"):
        PassivityLaw(4, 3, -1.0, 0.1)


def sampled_radius(overrides, kp, kd, period=1 / 32):
    """Spectral radius of the loop sampled with a zero-order hold (the controller's command is
    computed from the state at t_k and held over the period)."""
    model = build_model(load_scene("scenes/thesis_fe.yaml", overrides))
    A, B = model.linearized().state_space()
    n = A.shape[0]
    big = sla.expm(np.block([[A, B[:, 3:4]], [np.zeros((1, n + 1))]]) * period)
    Ad, Bd = big[:n, :n], big[:n, n:]
    gain = np.zeros(n)
    gain[model.phi_index], gain[model.n_dof + model.phi_index] = kp, kd
    return np.max(np.abs(np.linalg.eigvals(Ad - Bd @ gain[None, :])))


def test_sampled_loop_is_stable_below_the_injection_bound_and_the_factory_rejects_above():
    plants = (["model.type=lumped", "damping.model=rayleigh"], ["model.type=fe"],
              ["model.type=modal", "model.modes=3"])
    for overrides in plants:
        assert sampled_radius(overrides, 0.0, 0.05) < 1.0  # the scene default, k_d T/J = 1.1
    assert sampled_radius(plants[0], 0.0, 0.15) > 1.0      # k_d T/J = 3.4: the guard's reason
    scene = load_scene("scenes/thesis_lqg.yaml", ["controller.type=passivity",
                                                  "controller.injection_damping=0.15"])
    with pytest.raises(InputError, match="injection_damping"):
        make_controller(scene, build_model(load_scene("scenes/thesis_fe.yaml")))
