"""LQG's regulator half: discrete LQR on the design model (thesis §4.4, eq. 5.228–5.232).

The design model (linearised scene model or identified structure + pendulum, eq. 5.199–5.207)
is discretised with a zero-order hold at the control period (eq. 5.213); with Q = Sᵀ diag(Q_z) S
on the physical state and R = Q_u, the gain K = (R + BᵀPB)⁻¹ BᵀPA from the discrete Riccati
solution P gives u = −K ẑ (the thesis writes u = F∞ ẑ, F∞ = −K).

Optional feedforward of the measured excitation d (load cell): for x⁺ = A x + B u + E d with d
held, the optimal law is u = −K x − K_d d with K_d = (R + BᵀPB)⁻¹ Bᵀ (I − A_clᵀ)⁻¹ P E,
A_cl = A − BK (the LQ regulator with a known constant disturbance); for the harmonic load it is
the quasi-static approximation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from stillframe.design.coordinates import physical_selector
from stillframe.design.discrete import first_order_hold
from stillframe.design.riccati import solve_dare
from stillframe.dynamics.models import FrameModel


@dataclass(frozen=True)
class LQRDesign:
    """Gains of u = −K z − K_d d, the Riccati solution P and the discrete model used."""

    gain: np.ndarray
    feedforward: np.ndarray
    riccati: np.ndarray
    A: np.ndarray
    B: np.ndarray
    E: np.ndarray


def design_lqr(model: FrameModel, period: float, state_weights: Sequence[float],
               input_weight: float, input_index: int, excited_floor: int) -> LQRDesign:
    """DLQR for input ``input_index`` of u = [f1, f2, f3, torque] (3: the pendulum torque)."""
    A_c, B_c = model.linearized().state_space()
    d = first_order_hold(A_c, B_c, period)
    A, B, E = d.phi, d.gamma0[:, [input_index]], d.gamma0[:, [excited_floor - 1]]
    S = physical_selector(model)
    Q = S.T @ np.diag(state_weights) @ S
    R = np.array([[input_weight]])
    P = solve_dare(A, B, Q, R, what="LQR design")
    BtP = B.T @ P
    K = np.linalg.solve(R + BtP @ B, BtP @ A)
    A_cl = A - B @ K
    K_d = np.linalg.solve(R + BtP @ B, B.T @ np.linalg.solve(np.eye(A.shape[0]) - A_cl.T, P @ E))
    return LQRDesign(K, K_d, P, A, B, E)


class LQGLaw:
    """u = −K ẑ (− K_d F with feedforward of the measured excitation force F)."""

    def __init__(self, design: LQRDesign, feedforward: bool) -> None:
        self.design = design
        self.feedforward = feedforward

    def __call__(self, z: np.ndarray, force: float) -> tuple[float, bool]:
        u = -float(self.design.gain[0] @ z)
        if self.feedforward:
            u -= float(self.design.feedforward[0, 0]) * force
        return u, False
