"""Modes of a model linearised at rest: frequencies, damping ratios, shapes at floors and φ."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from stillframe.dynamics.models import FrameModel


def modal_table(model: FrameModel) -> dict:
    """Undamped modes of (K, M) with the damping ratio of the matching damped eigenvalue.

    Shapes are the floor displacements and φ, normalised to floor 1 (the thesis's ρⱼ with its
    sign, eq. 5.67–5.70). Damping ratios come from the eigenvalues of the first-order system,
    ζ = −Re λ / |λ|, paired with the undamped modes in order of frequency; the overdamped top
    modes of a fine FE mesh (stiffness-proportional damping) have no complex pair and get the
    modal projection ζ = φᵀCφ / (2ω) of the mass-normalised shape instead.
    """
    lin = model.linearized()
    w2, shapes = sla.eigh(lin.stiffness, lin.mass)
    omega = np.sqrt(np.clip(w2, 0.0, None))
    A, _ = lin.state_space()
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    zeta = -lam.real / np.abs(lam)
    projected = np.einsum("ij,ik,kj->j", shapes, lin.damping, shapes) / (2.0 * omega)
    zeta = np.concatenate([zeta, projected[zeta.size :]])
    picks = [*model.floor_index, model.phi_index]
    rows = shapes[picks, :]
    normalised = rows / rows[0]
    return {
        "model": model.name,
        "dofs": int(model.n_dof),
        "frequencies_hz": (omega / (2 * np.pi)).tolist(),
        "damping_ratios": zeta.tolist(),
        "mode_shapes": normalised.T.tolist(),
    }
