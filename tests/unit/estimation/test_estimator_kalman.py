"""Kalman filters on a linear model: the discretisation against scipy and an ODE solver, the
stationary filter against python-control's dlqe, the time-varying one against a textbook filter
written out here, and the gating of stale, missing and non-finite samples."""

from __future__ import annotations

import control
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import cont2discrete

from stillframe.contract.signals import full_inputs
from stillframe.design.discrete import first_order_hold
from stillframe.design.identified import frame_for
from stillframe.dynamics.models import build_model
from stillframe.estimation.factory import initial_physical, make_estimator
from stillframe.estimation.kalman import SteadyStateKalman, TimeVaryingKalman
from stillframe.plant.frame_plant import FramePlant
from tests.support.scenes import lumped_scene, sample, thesis_scene

PERIOD = 1.0 / 32


def test_first_order_hold_matches_scipy_zoh_and_an_ode_solution_for_a_ramp() -> None:
    A, B = build_model(lumped_scene()).linearized().state_space()
    d = first_order_hold(A, B, PERIOD)
    Ad, Bd, *_ = cont2discrete((A, B, np.eye(8), np.zeros((8, 4))), PERIOD, method="zoh")
    np.testing.assert_allclose(d.phi, Ad, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(d.gamma0, Bd, rtol=1e-10, atol=1e-14)
    x0 = np.linspace(-1e-3, 1e-3, 8)
    u0, u1 = np.array([0.3, 0.0, -0.1, 0.02]), np.array([-0.2, 0.1, 0.4, -0.01])
    ramp = solve_ivp(lambda t, x: A @ x + B @ (u0 + (u1 - u0) * t / PERIOD), (0, PERIOD), x0,
                     rtol=1e-12, atol=1e-15).y[:, -1]
    np.testing.assert_allclose(d.phi @ x0 + d.gamma0 @ u0 + d.gamma1 @ (u1 - u0), ramp,
                               rtol=1e-8, atol=1e-13)


def _mkr_filter(kind: type) -> SteadyStateKalman:
    scene = thesis_scene("thesis_lqg")
    design = frame_for("file", "thesis_mkr", scene, "design.file")
    return kind(design, scene.estimator, 1, initial_physical(scene), PERIOD)


def test_stationary_filter_against_python_control_dlqe() -> None:
    kf = _mkr_filter(SteadyStateKalman)
    d = kf.discrete(PERIOD)
    L, P, _ = control.dlqe(d.phi, np.eye(8), kf.C, kf.Q, kf.R)
    np.testing.assert_allclose(kf.prior, P, rtol=1e-7, atol=1e-14)
    # dlqe's predictor gain L = Φ K for our filter (current-estimate) gain K
    np.testing.assert_allclose(d.phi @ kf.gain, L, rtol=1e-7, atol=1e-10)


def _textbook(kf, ys, forces, controls, masks):
    """A plain Kalman filter written from the equations, same model and noise."""
    x, P = kf.x.copy(), kf.P.copy()
    out = []
    for k, (y, f, c, m) in enumerate(zip(ys, forces, controls, masks, strict=True)):
        if k:
            d = kf.discrete(PERIOD)
            u0 = full_inputs(c, forces[k - 1], 1)
            u1 = full_inputs(c, f, 1)
            x = d.phi @ x + d.gamma0 @ u0 + d.gamma1 @ (u1 - u0)
            P = d.phi @ P @ d.phi.T + kf.Q
        C, R = kf.C[m], kf.R[np.ix_(m, m)]
        innovation = (y - kf.D @ full_inputs(c, f, 1))[m] - C @ x
        K = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
        x = x + K @ innovation
        P = (np.eye(8) - K @ C) @ P
        out.append(x)
    return np.array(out), P


def _plant_data(n: int):
    scene = thesis_scene("thesis_lqg", ["duration=3", "controller.type=none"])
    plant = FramePlant(scene)
    rng = np.random.default_rng(5)
    ys, forces, controls, masks = [], [], [], []
    control_now = np.zeros(2)
    for k in range(n):
        s = plant.sample()
        ys.append(s.measurements)
        forces.append(s.force)
        controls.append(control_now.copy())
        mask = np.ones(4, dtype=bool)
        if k % 7 == 3:
            mask[rng.integers(4)] = False
        masks.append(mask)
        control_now = np.array([0.05 * np.sin(k / 5), 0.0])
        plant.advance(control_now)
    return ys, forces, controls, masks


def test_time_varying_filter_against_a_textbook_filter_with_partial_updates() -> None:
    ys, forces, controls, masks = _plant_data(60)
    kf = _mkr_filter(TimeVaryingKalman)
    expected, P_end = _textbook(kf, ys, forces, controls, masks)
    got = []
    for k, (y, f, c, m) in enumerate(zip(ys, forces, controls, masks, strict=True)):
        got.append(kf.step(sample(k * PERIOD, y, f, np.append(m, True)), c).z)
    np.testing.assert_allclose(np.array(got), expected, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(kf.P, P_end, rtol=1e-6, atol=1e-16)
    assert kf.counters.missing == sum(int((~m).sum()) for m in masks)


def test_time_varying_covariance_converges_to_the_stationary_one() -> None:
    tv, ss = _mkr_filter(TimeVaryingKalman), _mkr_filter(SteadyStateKalman)
    y = np.zeros(4)
    for k in range(400):
        tv.step(sample(k * PERIOD, y), np.zeros(2))
    posterior = ss.prior - ss.gain @ ss.C @ ss.prior
    np.testing.assert_allclose(tv.P, posterior, rtol=1e-6, atol=1e-6 * np.abs(posterior).max())


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_channel_is_rejected_counted_and_equals_a_partial_update(bad: float) -> None:
    scene = lumped_scene(["estimator.type=kf"])
    design = build_model(scene)
    a, b = make_estimator(scene, design), make_estimator(scene, design)
    y = np.array([0.01, -0.02, 0.03, 0.001])
    a.step(sample(0.0, y), np.zeros(2))
    b.step(sample(0.0, y), np.zeros(2))
    broken = y.copy()
    broken[2] = bad
    ea = a.step(sample(PERIOD, broken, 0.05), np.zeros(2))
    eb = b.step(sample(PERIOD, y, 0.05, np.array([True, True, False, True, True])), np.zeros(2))
    np.testing.assert_array_equal(ea.z, eb.z)
    assert np.all(np.isfinite(ea.z)) and np.all(np.isfinite(ea.covariance))
    assert a.counters.non_finite == 1 and a.counters.rejected == 1
    assert b.counters.missing == 1 and b.counters.rejected == 0


def test_stale_sample_is_rejected_and_counted() -> None:
    scene = lumped_scene(["estimator.type=tvkf"])
    est = make_estimator(scene, build_model(scene))
    first = est.step(sample(0.5, np.zeros(4)), np.zeros(2))
    assert est.step(sample(0.5, np.ones(4)), np.zeros(2)) is None
    assert est.step(sample(0.4, np.ones(4)), np.zeros(2)) is None
    assert est.counters.stale == 2
    np.testing.assert_array_equal(est.estimate().z, first.z)


def test_noise_set_at_run_time_redesigns_the_filters() -> None:
    """New W0, V0 (eq. 5.221-5.222) while running: the stationary filter's P∞ and gain are
    python-control's dlqe for the new Q, R; the time-varying filter predicts with the new Q."""
    process, measurement = [2e-3] * 4 + [5e-4] * 4, [0.05, 0.02, 0.05, 1e-3]
    kf = _mkr_filter(SteadyStateKalman)
    kf.set_noise(process, measurement)
    T = kf.T
    Q = T @ np.diag(np.square(process)) @ T.T
    R = np.diag(np.square(measurement))
    d = kf.discrete(PERIOD)
    L, P, _ = control.dlqe(d.phi, np.eye(8), kf.C, Q, R)
    np.testing.assert_allclose(kf.prior, P, rtol=1e-7, atol=1e-14)
    np.testing.assert_allclose(d.phi @ kf.gain, L, rtol=1e-6, atol=1e-12)
    tv = _mkr_filter(TimeVaryingKalman)
    P0 = tv.P.copy()
    tv.set_noise(process, measurement)
    tv.predict(PERIOD, 0.0, 0.0, np.zeros(2))
    np.testing.assert_allclose(tv.P, d.phi @ P0 @ d.phi.T + Q, rtol=1e-12, atol=1e-20)
    np.testing.assert_array_equal(tv.kf.R, R)


def _swinging_run(n: int) -> tuple[list, list, np.ndarray]:
    """Samples, commands and true physical states of the rig driven by a 1.1 Hz torque: the
    pendulum swings at up to about 20 rad/s, the floors at up to about 1 m/s."""
    scene = thesis_scene("thesis_lqg", ["duration=20", "controller.type=none"])
    plant = FramePlant(scene)
    samples, controls = [], []
    command = np.zeros(2)
    for k in range(n):
        samples.append(plant.sample())
        controls.append(command.copy())
        command = np.array([0.05 * np.sin(2 * np.pi * 1.1 * k * PERIOD), 0.0])
        plant.advance(command)
    return samples, controls, np.array([s.truth for s in samples])


@pytest.mark.parametrize("start", [100, 137, 171])
def test_a_filter_started_from_a_sample_converges_and_its_covariance_holds_the_error(
        start: int) -> None:
    """A filter that joins a running loop (the estimator node restarted) starts from one sample:
    φ from the encoder, the floors from the accelerations, the velocities unknown.

    The error of every state stays within 4.5 of its own standard deviations over the next 150
    samples (the restart covariance allows for the unknown velocities), φ's within 1e-2 rad.
    The stationary filter propagates its covariance as filterpy's time-varying filter does (the
    same estimates to 1e-9 of the state's scale) until it reaches P∞, within 200 samples. A
    stationary filter restarted with P∞ and zero velocities claims a 1e-3 rad spread and is
    0.1 rad off."""
    samples, controls, truth = _swinging_run(start + 150)
    ss, tv, frozen = (_mkr_filter(k) for k in (SteadyStateKalman, TimeVaryingKalman,
                                               SteadyStateKalman))
    estimates = [[f.initialise_from(samples[start], controls[start])] for f in (ss, tv, frozen)]
    frozen.converging, frozen.P = False, frozen.prior
    np.testing.assert_allclose(estimates[0][0].physical[3], samples[start].measurements[3],
                               rtol=1e-12)
    converged_at = None
    for k in range(start + 1, start + 150):
        for f, out in zip((ss, tv, frozen), estimates, strict=True):
            out.append(f.step(samples[k], controls[k]))
        if converged_at is None and not ss.converging:
            converged_at = k - start
    assert converged_at is not None and converged_at < 200
    scale = np.abs(truth[start:, :4]).max(axis=0)
    for a, b in zip(estimates[0][:converged_at], estimates[1][:converged_at], strict=True):
        assert np.all(np.abs(a.physical[:4] - b.physical[:4]) <= 1e-9 * scale)
    for out in estimates[:2]:
        errors = np.array([e.physical for e in out]) - truth[start:]
        spread = np.sqrt([np.diag(e.covariance) for e in out])
        assert np.abs(errors / spread).max() < 4.5
        assert np.abs(errors[:, 3]).max() < 1e-2
    errors = np.array([e.physical[3] for e in estimates[2]]) - truth[start:, 3]
    assert np.abs(errors).max() > 0.1 > 100 * np.sqrt(estimates[2][-1].covariance[3, 3])
