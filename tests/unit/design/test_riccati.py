"""DARE with nearly uncontrollable or unobservable modes: scipy, python-control, closed forms."""

from __future__ import annotations

import control
import numpy as np
import pytest

from stillframe.design.riccati import RiccatiWarning, solve_dare
from stillframe.errors import InputError


def scalar_dare(a: float, b: float, q: float, r: float) -> float:
    """Closed form of a²P − P − a²b²P²/(r + b²P) + q = 0 (stabilising root):
    b²P² − ((a² − 1) r + q b²) P − q r = 0."""
    c = (a * a - 1) * r + q * b * b
    return (c + np.sqrt(c * c + 4 * b * b * q * r)) / (2 * b * b)


def plant(eps: float) -> tuple[np.ndarray, ...]:
    """A lightly damped oscillator (well controlled) and an unstable mode 1.05 driven by eps."""
    th = 0.3
    A = np.zeros((3, 3))
    A[:2, :2] = 0.995 * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    A[2, 2] = 1.05
    B = np.array([[0.0], [1.0], [eps]])
    return A, B, np.eye(3), np.array([[0.1]])


def test_well_posed_solution_matches_python_control() -> None:
    A, B, Q, R = plant(1.0)
    P = solve_dare(A, B, Q, R)
    X, _, _ = control.dare(A, B, Q, R)
    np.testing.assert_allclose(P, X, rtol=1e-9, atol=1e-9)


def test_nearly_uncontrollable_unstable_mode_warns_and_matches_the_closed_form() -> None:
    eps = 1e-8
    A, B, Q, R = plant(eps)
    A[:2, :2] = 0.0  # decouple: the unstable mode alone sees eps (the oscillator has no input)
    B[1, 0] = 0.0
    with pytest.warns(RiccatiWarning, match=r"mode λ = \(?1\.05.*nearly uncontrollable"):
        P = solve_dare(A, B, Q, R)
    exact = scalar_dare(1.05, eps, 1.0, 0.1)
    assert exact > 1e14  # ∝ r (a² − 1) / eps²: the gain is huge and sensitive
    assert P[2, 2] == pytest.approx(exact, rel=1e-6)
    X, _, _ = control.dare(A, B, Q, R)
    assert X[2, 2] == pytest.approx(exact, rel=1e-6)


def test_uncontrollable_unstable_mode_is_refused_by_name() -> None:
    A, B, Q, R = plant(0.0)
    with pytest.raises(InputError, match=r"mode λ = \(?1\.05.*uncontrollable .*not stabilisable"):
        solve_dare(A, B, Q, R)
    with pytest.raises(Exception):  # noqa: B017 - python-control fails too, less clearly
        control.dare(A, B, Q, R)


def test_unobservable_mode_on_the_unit_circle_is_refused_and_nearly_so_warns() -> None:
    """A pure rotation (|λ| = 1) that Q does not weight: no stabilising solution."""
    th = 0.2
    A = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    B = np.array([[0.0], [1.0]])
    R = np.array([[1.0]])
    with pytest.raises(InputError, match=r"unobservable in Q .*unit circle"):
        solve_dare(A, B, np.zeros((2, 2)), R)
    with pytest.warns(RiccatiWarning, match="nearly unobservable in Q"):
        P = solve_dare(A, B, 1e-14 * np.eye(2), R)
    X, _, _ = control.dare(A, B, 1e-14 * np.eye(2), R)
    np.testing.assert_allclose(P, X, rtol=1e-5, atol=1e-18)
    # the closed loop is (barely) stable
    K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    assert np.max(np.abs(np.linalg.eigvals(A - B @ K))) < 1.0


def test_non_finite_input_is_refused() -> None:
    A, B, Q, R = plant(1.0)
    A[0, 0] = np.nan
    with pytest.raises(InputError, match="A has non-finite entries"):
        solve_dare(A, B, Q, R)
