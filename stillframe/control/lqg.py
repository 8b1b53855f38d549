"""LQG's regulator half: discrete LQR on the design model (thesis §4.4, eq. 5.228–5.232).

The design model (linearised scene model or identified structure + pendulum, eq. 5.199–5.207)
is discretised with a zero-order hold at the control period (eq. 5.213); with Q = Sᵀ diag(Q_z) S
on the physical state and R = Q_u, the gain K = (R + BᵀPB)⁻¹ BᵀPA from the discrete Riccati
solution P gives u = −K ẑ (the thesis writes u = F∞ ẑ, F∞ = −K).

Optional feedforward of the measured excitation d (load cell): for x⁺ = A x + B u + E d with d
held, the optimal law is u = −K x − K_d d with K_d = (R + BᵀPB)⁻¹ Bᵀ (I − A_clᵀ)⁻¹ P E,
A_cl = A − BK (the LQ regulator with a known constant disturbance); for the harmonic load it is
the quasi-static approximation.

Anti-windup (``controller.anti_windup``, :class:`ConditionedLQGLaw`): the command −K ẑ is
conditioned on what can be realised (Hanus' conditioning technique, here on a static gain): it
is moved to the nearest command that the actuator applies unchanged (``actuators.torque_limit``,
``torque_rate_limit``, ``controller.limit``) and that keeps the pendulum angle predicted one
period ahead on the design model, φ⁺ = (A ẑ + E d)_φ + (B)_φ u, within ``controller.angle_limit``
(:mod:`stillframe.control.limits`). The estimator is fed the applied torque (observer-based
anti-windup, already so in the loop), so its state never winds up; what the conditioning adds is
that the loop stays where the linear design holds instead of throwing the light pendulum over
the top.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from stillframe.control.limits import CommandLimits, condition
from stillframe.design.coordinates import physical_selector
from stillframe.design.discrete import first_order_hold
from stillframe.design.riccati import solve_dare
from stillframe.dynamics.models import FrameModel

__all__ = ["ConditionedLQGLaw", "LQGLaw", "LQRDesign", "design_lqr", "state_weight"]


@dataclass(frozen=True)
class LQRDesign:
    """Gains of u = −K z − K_d d, the Riccati solution P and the discrete model used."""

    gain: np.ndarray
    feedforward: np.ndarray
    riccati: np.ndarray
    A: np.ndarray
    B: np.ndarray
    E: np.ndarray


def state_weight(model: FrameModel, state_weights: Sequence[float]) -> np.ndarray:
    """Q = Sᵀ diag(Q_z) S on the design state from the weights of the physical state."""
    S = physical_selector(model)
    return S.T @ np.diag(state_weights) @ S


def design_lqr(model: FrameModel, period: float, state_weights: Sequence[float],
               input_weight: float, input_index: int, excited_floor: int) -> LQRDesign:
    """DLQR for input ``input_index`` of u = [f1, f2, f3, torque] (3: the pendulum torque)."""
    A_c, B_c = model.linearized().state_space()
    d = first_order_hold(A_c, B_c, period)
    A, B, E = d.phi, d.gamma0[:, [input_index]], d.gamma0[:, [excited_floor - 1]]
    Q = state_weight(model, state_weights)
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


class ConditionedLQGLaw(LQGLaw):
    """LQG with anti-windup: −K ẑ conditioned on ``limits`` (module docstring)."""

    def __init__(self, design: LQRDesign, feedforward: bool, limits: CommandLimits,
                 angle_index: int) -> None:
        super().__init__(design, feedforward)
        self.limits = limits
        self.angle_row = design.A[angle_index]
        self.angle_force = float(design.E[angle_index, 0])
        self.angle_gain = float(design.B[angle_index, 0])
        self.previous = 0.0
        self.conditioned = 0  # commands changed by the conditioning

    def __call__(self, z: np.ndarray, force: float) -> tuple[float, bool]:
        u, _ = super().__call__(z, force)
        free = float(self.angle_row @ z) + self.angle_force * force
        u, changed = condition(u, self.limits, self.previous, free, self.angle_gain)
        self.conditioned += changed
        self.previous = u
        return u, False

    def set_limits(self, limits: CommandLimits) -> None:
        """Condition on ``limits`` from the next call on (the controller's limit changed)."""
        self.limits = limits
