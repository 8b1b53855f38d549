"""OKID, ERA and ERA/DC on noise-free data from a known 6-state MIMO system (2 inputs, 3 outputs),
against the exact Markov parameters and continuous eigenvalues, and ERA against python-control."""

from __future__ import annotations

import control
import numpy as np
import pytest
from scipy import linalg

from stillframe.errors import IdentificationError, InputError
from stillframe.identification.era import EraDimensions, factorize
from stillframe.identification.okid import OkidResult, observer_gain, okid
from stillframe.identification.pipeline import identify
from tests.support.ident_systems import (
    DAMPING,
    MASS,
    STIFFNESS,
    continuous,
    discrete,
    markov,
    modal_truth,
    simulate,
)

DT = 0.02
B2 = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])  # forces on DOFs 1 and 3


@pytest.fixture(scope="module")
def system():
    a_c, b_c, C, D = continuous(MASS, STIFFNESS, DAMPING, B2, "acceleration")
    A, B, Cd, Dd = discrete(a_c, b_c, C, D, DT)
    u = np.random.default_rng(1).standard_normal((1000, 2))
    y = simulate(A, B, Cd, Dd, u)
    return a_c, (A, B, Cd, Dd), u, y


def kept_condition(u: np.ndarray, y: np.ndarray, p: int) -> float:
    """σ₁/σ_r of OKID's regressor over the r singular values lstsq keeps (rcond=None)."""
    v = np.hstack([u, y])
    regressors = np.hstack([u[p:], *(v[p - j:len(u) - j] for j in range(1, p + 1))])
    s = np.linalg.svd(regressors, compute_uv=False)
    kept = s[s > np.finfo(float).eps * max(regressors.shape) * s[0]]
    return float(kept[0] / kept[-1])


@pytest.mark.parametrize("p", [2, 5, 20])
def test_okid_recovers_system_markov_parameters(system, p):
    """Noise-free data: the least-squares fit has zero residual, so the observer parameters are
    the truth to 2κ·u·√N relative (Golub & Van Loan Thm 5.3.1, κ over the kept directions; the
    exactly dependent ones are cut at lstsq's rcond); eq. 3.107's recursion to 80 system
    parameters carries them through the stable observer, adding at most one such error each."""
    _, (A, B, C, D), u, y = system
    exact = markov(A, B, C, D, 80)
    recovered = okid(u, y, p).system_markov(80)
    bound = 80 * 2 * kept_condition(u, y, p) * np.finfo(float).eps / 2 * np.sqrt(len(u))
    assert bound < 1e-10
    assert np.max(np.abs(recovered - exact)) <= bound * np.max(np.abs(exact))


def test_markov_recursions_and_observer_gain_against_closed_form(system):
    """Observer Markov parameters built from a known (A, B, C, D, G) by eqs. 3.88–3.91 give back
    C A^{k-1} B (eq. 3.107), C A^{k-1} G (eq. 3.108) and G itself (eq. 3.112)."""
    _, (A, B, C, D), _, _ = system
    P = linalg.solve_discrete_are(A.T, C.T, np.eye(6), np.eye(3))
    G = -A @ P @ C.T @ np.linalg.inv(C @ P @ C.T + np.eye(3))  # a stable observer, A + G C
    abar = A + G @ C
    p = 12
    ybar = np.zeros((p + 1, 3, 2 + 3))
    ybar[0, :, :2] = D
    power = np.eye(6)
    for k in range(1, p + 1):
        ybar[k] = np.hstack([C @ power @ (B + G @ D), -C @ power @ G])
        power = abar @ power
    result = OkidResult(observer_markov=ybar, observer_order=p, residual_rms=np.zeros(3))
    # eqs. 3.107/3.108 are exact up to k = p (beyond, they neglect Abar^p)
    exact_gain = np.array([C @ np.linalg.matrix_power(A, k - 1) @ G for k in range(1, p + 1)])
    scale = np.max(np.abs(exact_gain))
    assert np.allclose(result.system_markov(p + 1), markov(A, B, C, D, p + 1), rtol=0, atol=1e-12)
    assert np.allclose(result.observer_gain_markov(p + 1)[1:], exact_gain, rtol=0,
                       atol=1e-12 * scale)
    assert np.allclose(observer_gain(A, C, result.observer_gain_markov(p + 1)), G, rtol=0,
                       atol=1e-10 * np.max(np.abs(G)))


@pytest.mark.parametrize(("method", "p", "combined"), [
    ("okid-era", 2, False), ("okid-era", 20, False), ("okid-eradc", 2, False),
    ("okid-eradc", 20, False), ("okid-eradc", 2, True)])
def test_identified_modes_match_the_exact_eigenvalues(system, method, p, combined):
    """(The combined variant needs p at the observability index on noise-free data: above it
    the least-squares OKID solution is not unique and [Y, Y0] has a higher rank.)"""
    a_c, (A, B, C, D), u, y = system
    f_true, z_true = modal_truth(a_c)
    ident = identify(u, y, DT, method, 6, observer_order=p, combined=combined)
    assert ident.B.shape == (6, 2) and ident.D.shape == (3, 2) and ident.G.shape == (6, 3)
    assert np.allclose(ident.modes.frequency_hz, f_true, rtol=1e-8, atol=0)
    assert np.allclose(ident.modes.damping_ratio, z_true, rtol=1e-6, atol=0)
    # the realization reproduces the Markov parameters (coordinate-free comparison)
    assert np.allclose(markov(ident.A, ident.B, ident.C, ident.D, 60), markov(A, B, C, D, 60),
                       rtol=0, atol=1e-9 * np.max(np.abs(D)))


def test_auto_order_finds_six_with_a_large_gap(system):
    _, _, u, y = system
    ident = identify(u, y, DT, "okid-era", "auto", observer_order=20)
    assert ident.order == 6
    assert identify(u, y, DT, "okid-era", np.int64(6), observer_order=20).order == 6
    assert ident.order_gap > 1e6


def test_era_impulse_on_a_pulse_response(system):
    a_c, (A, B, C, D), _, _ = system
    u = np.zeros((600, 1))
    u[0, 0] = 2.5
    y = simulate(A, B[:, :1], C, D[:, :1], u)
    ident = identify(u, y, DT, "era-impulse", 6)
    f_true, _ = modal_truth(a_c)
    assert np.allclose(ident.modes.frequency_hz, f_true, rtol=1e-8, atol=0)
    assert ident.G is None


@pytest.mark.parametrize("noise", [0.0, 1e-3])
def test_era_agrees_with_python_control(system, noise):
    """Same Markov parameters and Hankel sizes (python-control's m rows, n columns = our alpha,
    beta): the eigenvalues and the Markov parameters of the two realizations agree, with or
    without noise on the parameters."""
    _, (A, B, C, D), _, _ = system
    exact = markov(A, B, C, D, 61)
    rng = np.random.default_rng(7)
    params = exact + noise * np.max(np.abs(exact)) * rng.standard_normal(exact.shape)
    yy = np.transpose(params, (1, 2, 0))  # python-control: (outputs, inputs, samples)
    ours = factorize(params, EraDimensions(alpha=30, beta=30), correlated=False).realize(6)
    theirs, sv = control.era(yy, 6, m=30, n=30)
    fac = factorize(params, EraDimensions(alpha=30, beta=30), correlated=False)
    assert np.allclose(fac.singular_values, sv, rtol=1e-10)
    ev_ours = np.sort_complex(np.linalg.eigvals(ours.A))
    ev_theirs = np.sort_complex(np.linalg.eigvals(theirs.A))
    assert np.allclose(ev_ours, ev_theirs, rtol=0, atol=1e-10)
    assert np.allclose(markov(ours.A, ours.B, ours.C, ours.D, 40),
                       markov(theirs.A, theirs.B, theirs.C, theirs.D, 40),
                       rtol=0, atol=1e-10 * np.max(np.abs(exact)))


@pytest.mark.slow
@pytest.mark.long      # OKID at growing observer orders on long records: a minute
def test_observer_gain_approaches_the_kalman_predictor_gain():
    """With process and measurement noise and a long record, OKID's observer is the steady-state
    Kalman predictor, G = -K (eq. 3.113). Compared coordinate-free: OKID's observer gain Markov
    parameters (eq. 3.108) and C A^k G of the identified model against -C A^k K, K from the
    Riccati equation (scipy). The identified model's G is the refinement's: the process noise
    leaves the output-error model's errors coloured, so the innovation form is refined too and G
    is its -K where BIC keeps it (OKID's gain in the refined coordinates otherwise); either way a
    consumer of the model file gets the predictor gain. Both agree to the estimation error of
    20000 samples (about 4 %)."""
    b2 = np.array([[1.0], [0.0], [0.0]])
    a_c, b_c, C, D = continuous(MASS, STIFFNESS, DAMPING * 20, b2, "displacement")
    A, B, Cd, _ = discrete(a_c, b_c, C, D, 0.05)
    rng = np.random.default_rng(3)
    n_samples, q, r = 20000, 1e-6, 1e-6
    u = rng.standard_normal((n_samples, 1))
    w = np.sqrt(q) * rng.standard_normal((n_samples, 6))
    v = np.sqrt(r) * rng.standard_normal((n_samples, 3))
    x = np.zeros(6)
    y = np.empty((n_samples, 3))
    for k in range(n_samples):
        y[k] = Cd @ x + v[k]
        x = A @ x + B @ u[k] + w[k]
    P = linalg.solve_discrete_are(A.T, Cd.T, q * np.eye(6), r * np.eye(3))
    K = A @ P @ Cd.T @ np.linalg.inv(Cd @ P @ Cd.T + r * np.eye(3))
    kalman = np.array([-Cd @ np.linalg.matrix_power(A, k) @ K for k in range(8)])
    scale = np.max(np.abs(kalman))
    okid_gain = okid(u, y, 10).observer_gain_markov(9)[1:]
    assert np.max(np.abs(okid_gain - kalman)) <= 0.06 * scale
    ident = identify(u, y, 0.05, "okid-era", 6, observer_order=10)
    realized = np.array([ident.C @ np.linalg.matrix_power(ident.A, k) @ ident.G
                         for k in range(8)])
    assert np.max(np.abs(realized - kalman)) <= 0.06 * scale


def test_refuses_records_too_short_and_bad_requests(system):
    _, _, u, y = system
    with pytest.raises(IdentificationError, match="too short"):
        identify(u[:40], y[:40], DT, "okid-era", 6, observer_order=10)
    with pytest.raises(InputError, match="m p >= n"):
        identify(u, y, DT, "okid-era", 12, observer_order=3)
    with pytest.raises(InputError, match="numerical rank"):
        identify(u, y, DT, "okid-era", 8, observer_order=20)
    with pytest.raises(InputError, match="unknown method"):
        identify(u, y, DT, "n4sid", 6)
    with pytest.raises(InputError, match="samples"):
        identify(u[:-1], y, DT, "okid-era", 6)
    with pytest.raises(IdentificationError, match="channel input 1: non-finite value nan in "
                       "sample 5"):
        identify(np.where(np.arange(1000)[:, None] == 5, np.nan, u), y, DT)
    with pytest.raises(InputError, match="dt"):
        identify(u, y, 0.0)
    with pytest.raises(InputError, match="single pulse"):
        identify(u[:, :1], y, DT, "era-impulse", 6)
    with pytest.raises(InputError, match="order"):
        identify(u, y, DT, "okid-era", 0)
