"""EKF on the nonlinear lumped model: the RK4 map's Jacobian against finite differences, the
prediction against an adaptive reference, the update against filterpy's ExtendedKalmanFilter,
agreement with the linear Kalman filter for small motion, and convergence from the thesis's
1 rad initial error in φ."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from stillframe.contract.signals import full_inputs
from stillframe.dynamics.integrators import reference_solution
from stillframe.dynamics.models import build_model
from stillframe.dynamics.systems import MechanicalSystem
from stillframe.errors import IntegrationError
from stillframe.estimation.ekf import ExtendedKalman
from stillframe.estimation.factory import initial_physical, make_estimator
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.plant.frame_plant import FramePlant
from tests.support.scenes import lumped_scene, thesis_scene

PERIOD = 1.0 / 32
STATE = np.array([1e-3, 2e-3, -1e-3, 0.6, 0.02, -0.01, 0.03, 1.5])  # a large pendulum swing
CONTROL = np.array([0.01, 0.2])


@pytest.fixture(scope="module")
def ekf() -> ExtendedKalman:
    scene = lumped_scene(["estimator.type=ekf"])
    return make_estimator(scene, build_model(scene))


def test_flow_jacobian_is_the_derivative_of_the_rk4_map(ekf: ExtendedKalman) -> None:
    _, Phi = ekf.flow(STATE, PERIOD, 0.1, -0.05, CONTROL)
    numeric = np.empty((8, 8))
    for j in range(8):
        step = 1e-7 * max(1.0, abs(STATE[j]))
        plus, minus = STATE.copy(), STATE.copy()
        plus[j] += step
        minus[j] -= step
        numeric[:, j] = (ekf.flow(plus, PERIOD, 0.1, -0.05, CONTROL)[0]
                         - ekf.flow(minus, PERIOD, 0.1, -0.05, CONTROL)[0]) / (2 * step)
    np.testing.assert_allclose(Phi, numeric, rtol=1e-6, atol=1e-6 * np.abs(Phi).max())


def test_prediction_matches_an_adaptive_reference_solution(ekf: ExtendedKalman) -> None:
    model = ekf.model
    system = MechanicalSystem(model, lambda t: np.array([0.1 - 0.15 * t / PERIOD, 0.0, 0.0]))
    system.control = full_inputs(CONTROL, 0.0, 1)
    reference = reference_solution(system, STATE, np.array([0.0, PERIOD]))[-1]
    predicted, _ = ekf.flow(STATE, PERIOD, 0.1, -0.05, CONTROL)
    # RK4 with 5 ms substeps (7 per 31.25 ms): error ~ (omega h)^4 of the 8.8 Hz mode
    np.testing.assert_allclose(predicted, reference, rtol=0, atol=2e-4 * np.abs(reference).max())


@pytest.mark.parametrize("present", [[True, True, True, True], [True, False, True, False]])
def test_update_matches_filterpy_extended_kalman_filter(ekf: ExtendedKalman,
                                                        present: list[bool]) -> None:
    mask = np.array(present)
    rng = np.random.default_rng(3)
    root = rng.normal(size=(8, 8)) * 1e-3
    prior_P = root @ root.T + 1e-8 * np.eye(8)
    ekf.x, ekf.P = STATE.copy(), prior_P.copy()
    y = np.array([0.3, -0.2, 0.5, 0.61])
    h, H = ekf.measurement(STATE, 0.07, CONTROL)
    ekf.update(y, mask, 0.07, CONTROL)
    reference = ExtendedKalmanFilter(dim_x=8, dim_z=int(mask.sum()))
    reference.x, reference.P = STATE.copy(), prior_P.copy()
    reference.update(y[mask], HJacobian=lambda x: H[mask], Hx=lambda x: h[mask],
                     R=ekf.R[np.ix_(mask, mask)])
    np.testing.assert_allclose(ekf.x, reference.x, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(ekf.P, reference.P, rtol=1e-7, atol=1e-16)


def _estimates(kind: str, scene_overrides: list[str], n: int) -> tuple[np.ndarray, np.ndarray]:
    scene = lumped_scene([f"estimator.type={kind}", *scene_overrides])
    plant = FramePlant(scene)
    estimator = make_estimator(scene, build_model(scene))
    truth, est = [], []
    for _ in range(n):
        s = plant.sample()
        est.append(estimator.step(s, np.zeros(2)).physical)
        truth.append(s.truth)
        plant.advance(np.zeros(2))
    return np.array(truth), np.array(est)


def test_small_motion_ekf_agrees_with_the_linear_kalman_filter() -> None:
    truth, ekf = _estimates("ekf", [], 160)
    _, kf = _estimates("tvkf", [], 160)
    scale = np.abs(truth).max(axis=0)
    # same data, same noise model: the two differ by the RK4-vs-exact prediction and the
    # nonlinearity at phi of a few mrad
    assert np.max(np.abs(ekf - kf)[:, :3] / scale[:3]) < 0.02
    assert np.max(np.abs(ekf - truth)[80:, :3] / scale[:3]) < 0.1


def test_ekf_recovers_from_the_thesis_one_radian_error_in_phi() -> None:
    scene = thesis_scene("thesis_euk_ekf", ["controller.type=none", "duration=5"])
    plant = FramePlant(scene)
    estimator = make_estimator(scene, build_model(scene))
    assert estimator.x[3] == pytest.approx(initial_physical(scene)[3] + 1.0)
    errors = []
    for _ in range(160):
        s = plant.sample()
        errors.append(estimator.step(s, np.zeros(2)).physical - s.truth)
        plant.advance(np.zeros(2))
    errors = np.array(errors)
    # the encoder (std 1e-3 rad) against a prior of std 1 rad: one update removes the error
    assert abs(errors[0][3]) < 1e-2
    assert np.max(np.abs(errors[-32:, 3])) < 5e-3
    assert np.max(np.abs(errors[-32:, :3])) < 5e-5  # floors: < 2.5 % of their 2 mm amplitude


def test_an_estimate_that_leaves_the_finite_range_ends_the_run_with_the_estimators_line() -> None:
    """The EKF of the EUK scene on the identified linear plant driven by white noise leaves the
    finite range (its pendulum angle runs away, and sin φ of an infinite φ has no value): the
    one-process loop ends with an IntegrationError naming ``estimator.type`` and the time, as
    the estimator node does (exit code 4), not a ``ValueError`` from inside the model."""
    scene = thesis_scene("thesis_euk_ekf", [
        "duration=2", "integrator.dt=0.0078125", "controller.start=0.9777146821174447",
        "evaluation.window=0.9777146821174447", "excitation.type=white_noise",
        "plant.model=file"])
    with pytest.raises(IntegrationError, match=r"^estimator\.type: the ExtendedKalman estimate "
                                               r"left the finite range at t = \d"):
        run_closed_loop(scene)
