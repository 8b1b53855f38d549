"""LQG regulator: the gain against python-control's dlqr on python-control's own ZOH model, a
stable closed loop, and the disturbance feedforward against the static optimum it must reach."""

from __future__ import annotations

import control
import numpy as np
import scipy.optimize as so

from stillframe.contract.signals import Estimate
from stillframe.control.factory import TORQUE_INPUT, make_controller
from stillframe.control.lqg import design_lqr
from stillframe.design.coordinates import physical_selector
from stillframe.design.identified import frame_for
from tests.support.scenes import thesis_scene

PERIOD = 1.0 / 32


def _design():
    scene = thesis_scene("thesis_lqg")
    model = frame_for("file", "thesis_mkr", scene, "design.file")
    c = scene.controller
    return scene, model, design_lqr(model, PERIOD, c.state_weights, c.input_weight,
                                    TORQUE_INPUT, 1)


def test_gain_matches_python_control_dlqr() -> None:
    scene, model, design = _design()
    A, B = model.linearized().state_space()
    sampled = control.ss(A, B[:, [TORQUE_INPUT]], np.eye(8), 0).sample(PERIOD, method="zoh")
    Q = np.diag(scene.controller.state_weights)  # the identified model's state is physical
    K, S, E = control.dlqr(sampled.A, sampled.B, Q, scene.controller.input_weight)
    np.testing.assert_allclose(design.gain, K, rtol=1e-6, atol=1e-9 * np.abs(K).max())
    np.testing.assert_allclose(design.riccati, S, rtol=1e-6, atol=1e-9 * np.abs(S).max())
    assert np.max(np.abs(E)) < 1.0


def test_feedforward_reaches_the_static_optimum_for_a_constant_disturbance() -> None:
    # on the floor-3 force (a held hinge torque moves only phi at equilibrium: optimum u = 0)
    scene, model, _ = _design()
    c = scene.controller
    design = design_lqr(model, PERIOD, c.state_weights, c.input_weight, 2, 1)
    A, B, E = design.A, design.B, design.E
    S = physical_selector(model)
    Q, R = S.T @ np.diag(scene.controller.state_weights) @ S, scene.controller.input_weight
    d = 0.1
    A_cl = A - B @ design.gain
    x_ss = np.linalg.solve(np.eye(8) - A_cl, (E - B @ design.feedforward).ravel() * d)
    u_ss = float(-(design.gain @ x_ss + design.feedforward[0] * d)[0])

    # independent: minimise x'Qx + u'Ru over the equilibria x = A x + B u + E d
    def cost(u: np.ndarray) -> float:
        x = np.linalg.solve(np.eye(8) - A, (B[:, 0] * u[0] + E[:, 0] * d))
        return float(x @ Q @ x + R * u[0] ** 2)

    best = so.minimize(cost, np.zeros(1), method="Nelder-Mead",
                       options={"xatol": 1e-12, "fatol": 1e-20}).x[0]
    assert abs(best) > 1e-3  # a real trade-off, not u = 0
    np.testing.assert_allclose(u_ss, best, rtol=1e-4)


def test_controller_applies_minus_k_times_the_estimate_after_the_start() -> None:
    scene, model, design = _design()
    controller = make_controller(scene, model)
    z = np.linspace(-1e-3, 1e-3, 8)
    before = controller.command(10.0, Estimate(10.0, z, z), 0.1)
    after = controller.command(30.0, Estimate(30.0, z, z), 0.1)
    assert before.torque == 0.0 and not before.enabled
    # -K z to round-off: the law's dot product and this one may be summed by different BLAS
    # routines, each within a few eps of the sum of |K_i z_i|
    bound = 8 * np.finfo(float).eps * float(np.abs(design.gain[0]) @ np.abs(z))
    assert after.enabled and abs(after.torque + (design.gain @ z)[0]) <= bound
