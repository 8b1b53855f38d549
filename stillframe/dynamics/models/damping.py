"""Structural damping matrices, checked so that no mode gets negative damping (README, damping).

- ``rayleigh``: C = αM + βK (the thesis's identified α, β; eq. 5.237's story dashpots σ_i = βk_i
  plus floor-to-ground dampers αm_i on the lumped model). With β < 0 the damping ratio
  ζ(ω) = α/(2ω) + βω/2 turns negative above ω = √(α/−β) ≈ 58 rad/s, so a structure with modes
  up there is rejected.
- ``modal``: the first modes get ``modal_ratios`` exactly; the modes above get stiffness-
  proportional damping with ζ = ``high_mode_ratio`` at the first of them, growing with ω.
  C = β_h K + Σ_j (2ζ_jω_j − β_hω_j²) M φ_j φ_jᵀ M with mass-normalised φ_j.
- ``none``: C = 0.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from stillframe.config.scene import Damping
from stillframe.dynamics.models.structure import DampingParts, Structure
from stillframe.errors import InputError


def low_modes_first(stiffness: np.ndarray, mass: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ω² (ascending) and mass-normalised shapes φ of K φ = ω² M φ, for a positive definite K.

    Solved as the inverse problem M ψ = μ K ψ, μ = 1/ω², φ = ψ/√μ: a symmetric-definite solver
    is accurate relative to the largest eigenvalue, which is then the lowest mode. The direct
    ``eigh(K, M)`` factors M (condition number 3.5e11 for FE 200 per column) and moved the first
    FE 200 frequency by 1.5e-3 (docs/extremes.md). The highest modes are in turn accurate only to
    about ε (ω_max/ω)² (2.8e-4 on the top FE 200 frequency): use ``eigh(K, M)`` for those.
    """
    mu, psi = sla.eigh(mass, stiffness)
    mu, psi = mu[::-1], psi[:, ::-1]
    return 1.0 / mu, psi / np.sqrt(mu)


def undamped_modes(structure: Structure) -> tuple[np.ndarray, np.ndarray]:
    """Circular frequencies (ascending) and mass-normalised mode shapes of the structure."""
    w2, phi = low_modes_first(structure.stiffness, structure.mass)
    return np.sqrt(w2), phi


def rayleigh_ratio(omega: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """The damping ratio ζ(ω) = α/(2ω) + βω/2 that Rayleigh damping C = αM + βK gives at each ω
    [rad/s]."""
    return alpha / (2.0 * omega) + beta * omega / 2.0


def damping_parts(structure: Structure, damping: Damping) -> DampingParts:
    """The scene's ``damping`` section as :class:`DampingParts` of the structure."""
    return damping_parts_of(structure.mass, structure.stiffness, damping, structure.name)


def damping_parts_of(mass: np.ndarray, stiffness: np.ndarray, damping: Damping,
                     name: str) -> DampingParts:
    """:func:`damping_parts` of any positive definite (M, K), e.g. the pH frame's structure in
    the null space of its constraints; ``name`` is the model the error messages name."""
    n = mass.shape[0]
    if damping.model == "none":
        return DampingParts(0.0, 0.0, np.zeros((n, 0)), np.zeros(0))
    w2, phi = low_modes_first(stiffness, mass)
    omega = np.sqrt(w2)
    if damping.model == "rayleigh":
        zeta = rayleigh_ratio(omega, damping.alpha, damping.beta)
        bad = np.flatnonzero(zeta < 0)
        if bad.size:
            j = bad[0]
            raise InputError(
                f"damping.beta: Rayleigh damping (alpha={damping.alpha:g}, beta={damping.beta:g}) "
                f"gives structural mode {j + 1} at {omega[j] / (2 * np.pi):.4g} Hz the negative "
                f"damping ratio {zeta[j]:.3g}; use damping.model: modal for the {name} "
                "model"
            )
        return DampingParts(damping.alpha, damping.beta, np.zeros((n, 0)), np.zeros(0))
    ratios = np.asarray(damping.modal_ratios, dtype=float)
    r = min(ratios.size, omega.size)
    beta_high = 0.0
    if r < omega.size:
        beta_high = 2.0 * damping.high_mode_ratio / omega[r]
    extra = 2.0 * ratios[:r] * omega[:r] - beta_high * omega[:r] ** 2
    return DampingParts(0.0, beta_high, mass @ phi[:, :r], extra)
