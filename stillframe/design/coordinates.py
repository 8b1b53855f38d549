"""Between the 8 physical components [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇] and a design model's state
[q, q̇] (which for an FE design also holds the columns' inner DOFs)."""

from __future__ import annotations

import numpy as np

from stillframe.dynamics.models import FrameModel

__all__ = ["design_map", "physical_selector", "to_design"]


def physical_selector(model: FrameModel) -> np.ndarray:
    """S (8 × 2n) with physical = S z."""
    n = model.n_dof
    picks = [*model.floor_index, model.phi_index]
    S = np.zeros((8, 2 * n))
    S[np.arange(8), [*picks, *(n + i for i in picks)]] = 1.0
    return S


def to_design(model: FrameModel, physical: np.ndarray) -> np.ndarray:
    """z with the floors and φ given and the inner DOFs in static equilibrium with the floors."""
    n, ns = model.n_dof, model.n_struct
    z = np.zeros(2 * n)
    z[:ns] = model.static_fill(physical[:3])
    z[n : n + ns] = model.static_fill(physical[4:7])
    z[model.phi_index], z[n + model.phi_index] = physical[3], physical[7]
    return z


def design_map(model: FrameModel) -> np.ndarray:
    """T (2n × 8), the linear map of :func:`to_design`."""
    return np.column_stack([to_design(model, e) for e in np.eye(8)])
