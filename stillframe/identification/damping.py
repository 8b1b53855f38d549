"""Proportional (Rayleigh) damping: least-squares α, β from identified modes (thesis eqs.
3.208–3.213) and the damping matrix R = α M + β K (eq. 3.242)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import InputError

__all__ = ["fit_proportional_damping", "proportional_damping_matrix"]

Array = NDArray[np.float64]


def fit_proportional_damping(omega: Array, zeta: Array) -> tuple[float, float]:
    """α, β minimising ``sum (α / (2 ω_j) + β ω_j / 2 - ζ_j)^2`` (eqs. 3.209–3.213).

    ``omega`` are natural circular frequencies (rad/s), ``zeta`` the damping ratios.
    """
    omega = np.asarray(omega, dtype=float).ravel()
    zeta = np.asarray(zeta, dtype=float).ravel()
    if omega.size != zeta.size:
        raise InputError(f"{omega.size} frequencies but {zeta.size} damping ratios")
    if np.unique(omega).size < 2:
        raise InputError("proportional damping needs at least two distinct natural frequencies")
    if not (np.all(np.isfinite(omega)) and np.all(np.isfinite(zeta)) and np.all(omega > 0)):
        raise InputError("natural frequencies must be positive and finite, damping ratios finite")
    design = np.column_stack([1.0 / (2.0 * omega), omega / 2.0])  # eq. 3.210
    (alpha, beta), *_ = np.linalg.lstsq(design, zeta, rcond=None)  # eq. 3.213
    return float(alpha), float(beta)


def proportional_damping_matrix(M: Array, K: Array, alpha: float, beta: float) -> Array:
    """``R = α M + β K`` (eq. 3.242)."""
    M = np.asarray(M, dtype=float)
    K = np.asarray(K, dtype=float)
    if M.shape != K.shape or M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise InputError(f"M and K must be square matrices of one size, got {M.shape}, {K.shape}")
    return alpha * M + beta * K
