"""Controllers that respect the actuator (issue 30): the anti-windup LQG and the MPC on the
issue's torque-limited case, the MPC against independent peers (python-control's dlqr without
active limits, the QP's KKT conditions and scipy's trust-constr with them), its fallback, bad
input."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
from scipy.optimize import LinearConstraint, minimize

from stillframe.app.cli import main
from stillframe.config.scene import load_scene
from stillframe.contract.signals import Estimate
from stillframe.control.factory import make_controller
from stillframe.control.limits import CommandLimits
from stillframe.control.lqg import ConditionedLQGLaw, design_lqr, state_weight
from stillframe.control.mpc import MPCLaw, PredictionGrid
from stillframe.locations import SCENES_DIR
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.loop.wiring import design_model

THESIS = SCENES_DIR / "thesis_lqg.yaml"
ISSUE = ["plant.model=scene", "model.type=lumped", "design.model=lumped",
         "actuators.torque_limit=2"]
PERIOD = 1 / 32


def _run(extra: list[str]):
    history = run_closed_loop(load_scene(THESIS, [*ISSUE, *extra]))
    after = history.t >= 25.0
    return history, float(np.max(np.abs(history.truth[after, 3])))


@pytest.mark.parametrize("extra", [["controller.anti_windup=true"], ["controller.type=mpc"]])
def test_on_the_issues_case_the_pendulum_stays_and_every_floor_gains(extra) -> None:
    lqg, lqg_angle = _run([])
    assert lqg_angle > 2 * np.pi                      # plain saturated LQG throws it over
    assert min(lqg.evaluation["reduction_pct"]["displacement"]) < 0
    history, angle = _run(extra)
    evaluation = history.evaluation
    # measured: anti-windup 60.2 / 67.2 / 55.8 %, MPC 60.9 / 66.8 / 53.5 %, |phi| <= 0.51 rad
    assert min(evaluation["reduction_pct"]["displacement"]) > 40
    assert angle < 0.6                                 # angle_limit 0.5, soft in MPC
    assert np.max(np.abs(history.command[:, 0])) <= 2.0
    assert evaluation["plant"]["actuator_limited"] == 0  # nothing for the actuator to clip


def _lumped():
    scene = load_scene(THESIS, ISSUE)
    design = design_model(scene)
    c = scene.controller
    lqr = design_lqr(design, PERIOD, c.state_weights, c.input_weight, 3, 1)
    return scene, design, lqr


def test_mpc_without_active_limits_is_python_controls_lqr_for_every_horizon() -> None:
    scene, design, lqr = _lumped()
    Q = state_weight(design, scene.controller.state_weights)
    K, _, _ = ct.dlqr(lqr.A, lqr.B, Q, np.array([[scene.controller.input_weight]]))
    free = CommandLimits()
    rng = np.random.default_rng(3)
    for horizon in (1, 5, 30):
        law = MPCLaw(lqr, scene.controller.input_weight, limits=free,
                     grid=PredictionGrid(1, horizon), angle_index=design.phi_index)
        for _ in range(5):
            z = 1e-3 * rng.standard_normal(lqr.A.shape[0])
            u, _ = law(z, 0.0)
            assert u == pytest.approx(-float(K[0] @ z), rel=1e-6, abs=1e-12)
    assert law.fallbacks == 0


def test_the_qp_solution_meets_its_kkt_conditions_and_matches_scipy() -> None:
    scene, design, lqr = _lumped()
    limits = CommandLimits(saturation=0.5, step=0.3, angle=0.2)
    N = 10
    law = MPCLaw(lqr, scene.controller.input_weight, limits=limits, grid=PredictionGrid(1, N),
                 angle_index=design.phi_index)
    z = np.zeros(lqr.A.shape[0])
    z[design.phi_index] = 0.15
    z[0], z[2] = 0.01, -0.01                           # floors displaced: the LQR asks a lot
    q, lo, hi = law.bounds(z)
    u0, _ = law(z, 0.0)
    x = law.last
    assert law.fallbacks == 0
    P, A = law.qp_hessian, law.qp_matrix
    Ax = A @ x
    assert np.all(Ax >= lo - 1e-6) and np.all(Ax <= hi + 1e-6)      # primal feasibility
    assert np.max(np.abs(law.inputs(z, x))) <= 0.5 + 1e-6
    # stationarity P x + q + Aᵀ y = 0 with y ≥ 0 on upper bounds, ≤ 0 on lower bounds only
    result_y = law.dual
    np.testing.assert_allclose(P @ x + q + A.T @ result_y, 0.0, atol=1e-5 * np.max(np.abs(q)))
    upper, lower = result_y > 1e-6, result_y < -1e-6
    assert np.any(upper | lower)                                     # some limit is active
    assert np.all(np.abs(Ax[upper] - hi[upper]) < 1e-5)
    assert np.all(np.abs(Ax[lower] - lo[lower]) < 1e-5)
    # an independent solver on the same QP
    ref = minimize(lambda v: 0.5 * v @ P @ v + q @ v, np.zeros(N + 1), jac=lambda v: P @ v + q,
                   hess=lambda v: P, constraints=[LinearConstraint(A, lo, hi)],
                   method="trust-constr", options={"gtol": 1e-12, "xtol": 1e-14,
                                                   "maxiter": 5000})
    assert ref.status in (1, 2)
    assert u0 == pytest.approx(float(law.inputs(z, ref.x)[0]), abs=1e-5)


def test_a_failed_solve_falls_back_to_the_anti_windup_command_and_is_counted() -> None:
    scene = load_scene(THESIS, [*ISSUE, "controller.type=mpc", "controller.max_iter=1"])
    design = design_model(scene)
    controller = make_controller(scene, design)
    limits = CommandLimits.of(scene)
    c = scene.controller
    reference = ConditionedLQGLaw(design_lqr(design, PERIOD, c.state_weights, c.input_weight,
                                             3, 1), False, limits, design.phi_index)
    z = np.zeros(8)
    z[0] = 0.01
    for k in range(3):
        t = 25.0 + k * PERIOD                          # from controller.start on
        command = controller.command(t, Estimate(t, z, z), 0.0)
        expected, _ = reference(z, 0.0)
        assert command.torque == pytest.approx(expected, abs=1e-12)
        assert abs(command.torque) <= 2.0
    assert controller.counters.fallback == 3


@pytest.mark.parametrize(("setting", "named"), [
    ("actuators.torque_limit=-1", "actuators.torque_limit"),
    ("controller.angle_limit=-0.1", "controller.angle_limit"),
    ("controller.horizon_s=0", "controller.horizon_s"),
    ("controller.horizon_s=-0.5", "controller.horizon_s"),
    ("controller.horizon_s=0.03", "controller.horizon_s"),     # shorter than 1/32 s
    ("controller.prediction_steps=0", "controller.prediction_steps"),
    ("controller.input_weight=0", "controller.input_weight"),
    ("controller.state_weights=[1,1,1,-1,1,1,1,1]", "controller.state_weights"),
])
def test_bad_mpc_input_is_one_line_naming_the_key_exit_2(setting, named, capsys) -> None:
    code = main(["closed-loop", str(THESIS), "--set", "controller.type=mpc", "--set", setting])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and named in err[0]
