"""Known linear systems for the identification tests: M x'' + R x' + K x = B2 u, sampled exactly
(zero-order hold, scipy.signal.cont2discrete) and simulated with scipy.signal.dlsim."""

from __future__ import annotations

import numpy as np
from scipy import signal

# A 3-DOF chain with non-proportional damping (R is not a combination of M and K).
MASS = np.diag([1.2, 0.8, 1.5])
STIFFNESS = np.array([[900.0, -400.0, 0.0], [-400.0, 700.0, -300.0], [0.0, -300.0, 300.0]])
DAMPING = np.array([[1.5, -0.6, 0.0], [-0.6, 1.1, -0.3], [0.0, -0.3, 0.5]])


def continuous(M: np.ndarray, K: np.ndarray, R: np.ndarray, B2: np.ndarray, output: str,
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A_c, B_c, C, D (thesis eqs. 3.7, 3.8, 3.10, 3.11) measuring every DOF."""
    n = M.shape[0]
    minv = np.linalg.inv(M)
    a_c = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ K, -minv @ R]])
    b_c = np.vstack([np.zeros_like(B2), minv @ B2])
    if output == "displacement":
        C, D = np.hstack([np.eye(n), np.zeros((n, n))]), np.zeros_like(B2)
    elif output == "velocity":
        C, D = np.hstack([np.zeros((n, n)), np.eye(n)]), np.zeros_like(B2)
    else:
        C, D = a_c[n:], b_c[n:]
    return a_c, b_c, C, D


def discrete(a_c, b_c, C, D, dt):
    A, B, Cd, Dd, _ = signal.cont2discrete((a_c, b_c, C, D), dt, method="zoh")
    return A, B, Cd, Dd


def simulate(A, B, C, D, u):
    _, y, _ = signal.dlsim(signal.StateSpace(A, B, C, D, dt=1.0), u)
    return y


def markov(A, B, C, D, count):
    """Y_0 .. Y_{count-1} (eq. 3.73)."""
    out = [D]
    power = B
    for _ in range(1, count):
        out.append(C @ power)
        power = A @ power
    return np.array(out)


def modal_truth(a_c):
    """Frequencies (Hz) and damping ratios from the continuous eigenvalues, ascending."""
    lam = np.linalg.eigvals(a_c)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)
