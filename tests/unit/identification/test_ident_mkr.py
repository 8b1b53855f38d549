"""MKR (thesis §3.7) on a known 3-DOF system with non-proportional damping, and proportional
damping R = alpha M + beta K against the thesis's printed matrices (eqs. 5.176–5.180)."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.errors import IdentificationError, InputError
from stillframe.identification.damping import proportional_damping_matrix
from stillframe.identification.mkr import mkr
from stillframe.identification.pipeline import identify
from tests.support.ident_systems import DAMPING, MASS, STIFFNESS, continuous, discrete, simulate

DT = 0.02
FLOOR1 = np.array([[1.0], [0.0], [0.0]])


def exact_model(output: str, b2: np.ndarray = FLOOR1):
    return discrete(*continuous(MASS, STIFFNESS, DAMPING, b2, output), DT)


def assert_physical(model, tol):
    for got, want in ((model.M, MASS), (model.K, STIFFNESS), (model.R, DAMPING)):
        assert np.max(np.abs(got - want)) <= tol * np.max(np.abs(want))


@pytest.mark.parametrize("output", ["displacement", "velocity", "acceleration"])
def test_mkr_of_the_exact_model(output):
    A, B, C, _ = exact_model(output)
    assert_physical(mkr(A, B, C, DT, [0, 1, 2], [0], output), 1e-9)


def test_mkr_with_two_actuators_and_a_sensor_missing():
    """DOF 2 carries only an actuator: its W row comes from B (eq. 3.237)."""
    b2 = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    A, B, C, _ = exact_model("acceleration", b2)
    assert_physical(mkr(A, B, C[:2], DT, [0, 1], [0, 2]), 1e-9)


@pytest.mark.parametrize("method", ["okid-era", "okid-eradc", "era-impulse"])
def test_mkr_recovers_m_k_r_from_noise_free_data(method):
    """Identify from sampled force and accelerations, then MKR: M, K, R to 1e-6."""
    A, B, C, D = exact_model("acceleration")
    if method == "era-impulse":
        u = np.zeros((800, 1))
        u[0, 0] = 1.0
    else:
        u = np.random.default_rng(5).standard_normal((800, 1))
    y = simulate(A, B, C, D, u)
    ident = identify(u, y, DT, method, 6, observer_order=3)
    assert_physical(mkr(ident.A, ident.B, ident.C, DT, [0, 1, 2], [0]), 1e-6)


def test_mkr_refuses_what_it_cannot_do():
    A, B, C, _ = exact_model("acceleration")
    with pytest.raises(InputError, match="co-located"):
        mkr(A, B, C[1:], DT, [1, 2], [0])  # DOF 0 only actuated, no pair
    with pytest.raises(InputError, match="every DOF"):
        mkr(A, B, C[:2], DT, [0, 1], [0])  # DOF 2 not instrumented
    with pytest.raises(InputError, match="share a DOF"):
        mkr(A, B, C, DT, [0, 1, 1], [0])
    with pytest.raises(InputError, match="output type"):
        mkr(A, B, C, DT, [0, 1, 2], [0], "strain")
    with pytest.raises(InputError, match="3 outputs"):
        mkr(A, B, C, DT, [0, 1], [0])
    with pytest.raises(InputError, match="number the DOFs"):
        mkr(A, B, C, DT, [0, 1, 3], [0])
    overdamped = np.diag([0.5, 0.6, 0.7, 0.8, 0.9, 0.95])
    with pytest.raises(IdentificationError, match="underdamped"):
        mkr(overdamped, B, C, DT, [0, 1, 2], [0])


def test_proportional_damping_matrix_reproduces_the_thesis():
    """R = alpha M + beta K with the thesis's identified M, K, alpha, beta (eqs. 5.176–5.178)
    gives its printed R (eq. 5.180) to the printed digits."""
    M = np.array([[0.3871, -0.0156, 0.0011], [-0.0156, 0.2621, -0.0323],
                  [0.0011, -0.0323, 0.3790]])
    K = np.array([[534.061, -221.931, 25.696], [-221.931, 614.564, -432.792],
                  [25.696, -432.792, 422.005]])
    printed = np.array([[0.22356, 0.0487, -0.0063], [0.0487, 0.0785, 0.0932],
                        [-0.0063, 0.0932, 0.2480]])
    R = proportional_damping_matrix(M, K, 0.9751, -2.8815e-4)
    assert np.allclose(R, printed, rtol=0, atol=1e-4)
