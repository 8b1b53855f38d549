"""The discrete algebraic Riccati equation (thesis §4, LQR and Kalman gains) with checked inputs.

AᵀPA − P − AᵀPB (R + BᵀPB)⁻¹ BᵀPA + Q = 0 has a stabilising solution when (A, B) is
stabilisable and (A, Q) has no unobservable mode on the unit circle. Solvers given an input that
violates this, or nearly does, return huge or meaningless P without complaint (scipy) or fail with
a generic message. :func:`solve_dare` measures each mode's PBH margin first:

    controllability of λ:  σ_min([A − λI, B]) / ‖[A, B]‖      (modes with |λ| ≥ 1)
    observability of λ:    σ_min([A − λI; Q^½]) / ‖[A; Q^½]‖   (modes with |λ| = 1)

below ``SINGULAR`` it raises :class:`InputError` naming the mode; below ``NEAR`` it warns
(:class:`RiccatiWarning`) that P and the gain will be large and sensitive. The Kalman filter's
equation is the dual: pass Aᵀ, Cᵀ, the process and the measurement noise covariances.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg as sla

from stillframe.errors import InputError

__all__ = ["RiccatiWarning", "pbh_margins", "solve_dare"]

SINGULAR = 1e-10
NEAR = 1e-6
UNIT_CIRCLE = 1e-9


class RiccatiWarning(UserWarning):
    """A mode is nearly uncontrollable or nearly unobservable: P is large and ill-conditioned."""


def _psd_root(Q: np.ndarray) -> np.ndarray:
    w, V = np.linalg.eigh(0.5 * (Q + Q.T))
    if np.min(w) < -1e-12 * max(np.max(np.abs(w)), 1.0):
        raise InputError(f"Q: not positive semi-definite (eigenvalue {np.min(w):.3g})")
    return (V * np.sqrt(np.clip(w, 0.0, None))).T


def pbh_margins(A: np.ndarray, B: np.ndarray, Q: np.ndarray) -> list[dict]:
    """Per eigenvalue of A: |λ| and the relative PBH controllability and observability margins."""
    n = A.shape[0]
    root = _psd_root(Q)
    ab = np.linalg.norm(np.hstack([A, B]), 2)
    aq = np.linalg.norm(np.vstack([A, root]), 2)
    rows = []
    for lam in np.linalg.eigvals(A):
        shifted = A - lam * np.eye(n)
        ctrb = sla.svdvals(np.hstack([shifted, B]))[-1] / ab
        obsv = sla.svdvals(np.vstack([shifted, root]))[-1] / aq
        rows.append({"eigenvalue": complex(lam), "magnitude": float(abs(lam)),
                     "controllability": float(ctrb), "observability": float(obsv)})
    return rows


def solve_dare(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray,
               what: str = "Riccati equation") -> np.ndarray:
    """The stabilising P (scipy's solver), after the PBH checks; residual checked after."""
    A, B, Q, R = (np.atleast_2d(np.asarray(m, float)) for m in (A, B, Q, R))
    for name, m in (("A", A), ("B", B), ("Q", Q), ("R", R)):
        if not np.all(np.isfinite(m)):
            raise InputError(f"{what}: {name} has non-finite entries")
    if np.min(np.linalg.eigvalsh(0.5 * (R + R.T))) <= 0:
        raise InputError(f"{what}: R must be positive definite")
    for row in pbh_margins(A, B, Q):
        lam, size = row["eigenvalue"], row["magnitude"]
        checks = []
        if size >= 1.0 - UNIT_CIRCLE:
            checks.append(("uncontrollable", "controllability", "(A, B) is not stabilisable"))
        if abs(size - 1.0) <= UNIT_CIRCLE:
            checks.append(("unobservable in Q", "observability",
                           "(A, Q) has an unobservable mode on the unit circle"))
        for label, key, consequence in checks:
            margin = row[key]
            where = f"mode λ = {lam:.6g} (|λ| = {size:.6g})"
            if margin < SINGULAR:
                raise InputError(f"{what}: {where} is {label} (PBH margin {margin:.2g}): "
                                 f"{consequence}, no stabilising solution")
            if margin < NEAR:
                warnings.warn(f"{what}: {where} is nearly {label} (PBH margin {margin:.2g}); "
                              "the solution and the gains will be large and sensitive",
                              RiccatiWarning, stacklevel=2)
    try:
        P = sla.solve_discrete_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise InputError(f"{what}: scipy could not solve it ({exc})") from None
    residual = A.T @ P @ A - P - A.T @ P @ B @ np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A) + Q
    scale = max(np.linalg.norm(P), np.linalg.norm(Q), 1e-300)
    if not np.all(np.isfinite(P)) or np.linalg.norm(residual) > 1e-6 * scale:
        raise InputError(f"{what}: the solution is not accurate (relative residual "
                         f"{np.linalg.norm(residual) / scale:.2g})")
    return P
