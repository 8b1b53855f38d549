"""Stability limits and validity checks that let a scene fail early instead of blowing up.

- RK4 is stable for a linear mode λ while |R(hλ)| ≤ 1, R(z) = 1 + z + z²/2 + z³/6 + z⁴/24; on the
  imaginary axis (undamped modes) that is h ω ≤ 2√2 ≈ 2.828, on the negative real axis
  h |λ| ≤ 2.785. :func:`rk4_stable_step` finds the largest h for all eigenvalues of the model
  linearised at rest (the structure is linear, so this is exact for it).
- The columns are linear Euler–Bernoulli beams: a story drift beyond a few percent of the story
  height is outside the model's validity (:func:`drift_warning`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from stillframe.dynamics.models import FrameModel
from stillframe.errors import InputError

RK4_IMAGINARY_LIMIT = 2.0 * np.sqrt(2.0)
DRIFT_LIMIT = 0.02  # story drift / story height where linear beam theory stops being accurate


def rk4_growth(z: np.ndarray) -> np.ndarray:
    """|R(z)| of classical RK4."""
    return np.abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24)


def rk4_stable_step(model: FrameModel) -> float:
    """Largest h with |R(hλ)| ≤ 1 for every eigenvalue λ of the model linearised at rest."""
    A, _ = model.linearized().state_space()
    lam = np.linalg.eigvals(A)
    lam = lam[np.abs(lam) > 0]
    lo, hi = 0.0, 2.0 * RK4_IMAGINARY_LIMIT / np.max(np.abs(lam))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.all(rk4_growth(mid * lam) <= 1 + 1e-12) else (lo, mid)
    return lo


def check_rk4_step(model: FrameModel, dt: float) -> None:
    """Refuse an RK4 step beyond the predicted stability limit, before integrating."""
    limit = rk4_stable_step(model)
    if dt > limit:
        raise InputError(
            f"integrator.dt: {dt:g} s is beyond RK4's stability limit {limit:.3g} s for the "
            f"{model.name} model (its fastest mode); reduce integrator.dt or use "
            "integrator.method: midpoint")


def drift_warning(model: FrameModel, floors: np.ndarray, lengths: Sequence[float]) -> str | None:
    """A warning text if a story drift exceeds DRIFT_LIMIT of its height, else None."""
    drift = np.diff(np.column_stack([np.zeros(len(floors)), floors]), axis=1)
    ratio = np.max(np.abs(drift), axis=0) / np.asarray(lengths)
    story = int(np.argmax(ratio))
    if ratio[story] <= DRIFT_LIMIT:
        return None
    return (f"story {story + 1} drifts {ratio[story]:.1%} of its height (> {DRIFT_LIMIT:.0%}): "
            f"outside the linear column theory of the {model.name} model; results are "
            "qualitative")
