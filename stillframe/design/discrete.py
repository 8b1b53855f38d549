"""Discrete-time models for the filters and the LQR at the sample period.

:func:`first_order_hold` discretises ẋ = A x + B u exactly for inputs that vary linearly over
the period (the measured excitation between two load-cell samples); its first input matrix is
the zero-order-hold one (a command held over the period, thesis eq. 5.213).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

__all__ = ["Discrete", "first_order_hold"]


@dataclass(frozen=True)
class Discrete:
    """x⁺ = Φ x + Γ0 u_k + Γ1 (u_k+1 − u_k) for u linear on [t_k, t_k+1]."""

    phi: np.ndarray
    gamma0: np.ndarray
    gamma1: np.ndarray


def first_order_hold(A: np.ndarray, B: np.ndarray, period: float) -> Discrete:
    """Exact discretisation from one matrix exponential of the augmented system.

    With state [x, u, u̇] and u̇ = (u_k+1 − u_k)/T constant, exp([[A, B, 0], [0, 0, I], [0, 0, 0]] T)
    holds Φ = e^{AT}, Γ0 = ∫₀ᵀ e^{As} ds B (the ZOH matrix) and T Γ1 in its first block row.
    """
    n, m = B.shape
    big = np.zeros((n + 2 * m, n + 2 * m))
    big[:n, :n] = A
    big[:n, n : n + m] = B
    big[n : n + m, n + m :] = np.eye(m)
    E = sla.expm(big * period)
    return Discrete(E[:n, :n], E[:n, n : n + m], E[:n, n + m :] / period)
