"""Extended Kalman filter on the nonlinear model, discrete in time at the sample rate (thesis
eq. 5.253–5.273 in discrete form).

Prediction integrates ż = f(z, u) = [q̇, M(q)⁻¹Q(q, q̇, u)] (eq. 5.255) from one sample to the
next with classical RK4 substeps (the measured excitation linear in between, the command held)
together with the variational equation Φ̇ = ∂f/∂z Φ in the same stages, so Φ is the exact
Jacobian of the discrete RK4 map; then P = Φ P Φᵀ + Q. The measurement model is
h(z, u) = [floor accelerations a(q, q̇, u), φ] (eq. 5.257–5.258; the control's contribution, the
thesis's C_d a_c term, enters through u) with H = ∂h/∂z (eq. 5.271); Joseph-form update.

Written here rather than with filterpy's ``ExtendedKalmanFilter``: its predict is the linear
x = F x + B u, not an integration of the nonlinear equations, and its update fixes the
measurement dimension at construction while a partial update needs fewer rows. The update is
checked against filterpy's in the tests.
"""

from __future__ import annotations

import math

import numpy as np

from stillframe.config.loop_sections import Estimator
from stillframe.contract.signals import full_inputs
from stillframe.dynamics.models import FrameModel
from stillframe.estimation.base import Filter

__all__ = ["ExtendedKalman"]


class ExtendedKalman(Filter):
    """EKF with state z = [q, q̇] of the design :class:`FrameModel`."""

    def __init__(self, model: FrameModel, config: Estimator, excited_floor: int,
                 initial_physical: np.ndarray, period: float) -> None:
        super().__init__(model, config, excited_floor, initial_physical)
        self.max_substep = config.max_substep
        n = model.n_dof
        self.n = n
        self.acceleration_rows = n + np.asarray(model.floor_index)

    def dynamics(self, z: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """f(z, u) and ∂f/∂z: ∂a/∂q = M⁻¹(∂Q/∂q − ∂(M a)/∂q), ∂a/∂q̇ = M⁻¹ ∂Q/∂q̇."""
        m, n = self.model, self.n
        q, v = z[:n], z[n:]
        a = m.accelerations(q, v, u)
        dq, dv = m.force_jacobians(q, v)
        blocks = np.linalg.solve(m.mass_matrix(q),
                                 np.hstack([dq - m.mass_derivative_product(q, a), dv]))
        J = np.zeros((2 * n, 2 * n))
        J[:n, n:] = np.eye(n)
        J[n:] = blocks
        return np.concatenate([v, a]), J

    def flow(self, z: np.ndarray, dt: float, force0: float, force1: float,
             control: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """RK4 map over dt and its Jacobian Φ."""
        steps = max(1, math.ceil(dt / self.max_substep - 1e-9))
        h = dt / steps
        Phi = np.eye(z.size)

        def f(tau: float, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            force = force0 + (force1 - force0) * tau / dt
            return self.dynamics(state, full_inputs(control, force, self.excited_floor))

        z = z.copy()
        for s in range(steps):
            tau = s * h
            k1, J1 = f(tau, z)
            P1 = J1 @ Phi
            k2, J2 = f(tau + h / 2, z + h / 2 * k1)
            P2 = J2 @ (Phi + h / 2 * P1)
            k3, J3 = f(tau + h / 2, z + h / 2 * k2)
            P3 = J3 @ (Phi + h / 2 * P2)
            k4, J4 = f(tau + h, z + h * k3)
            P4 = J4 @ (Phi + h * P3)
            z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            Phi = Phi + h / 6 * (P1 + 2 * P2 + 2 * P3 + P4)
        return z, Phi

    def measurement(self, z: np.ndarray, force: float,
                    control: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """h(z, u) = [a1, a2, a3, φ] and H = ∂h/∂z."""
        f, J = self.dynamics(z, full_inputs(control, force, self.excited_floor))
        rows = self.acceleration_rows
        H = np.vstack([J[rows], np.eye(z.size)[self.model.phi_index]])
        return np.append(f[rows], z[self.model.phi_index]), H

    def predict(self, dt: float, force0: float, force1: float, control: np.ndarray) -> None:
        """Time update over ``dt`` [s]: the mean through the RK4 map (:meth:`flow`), P ← Φ P Φᵀ + Q
        with its Jacobian Φ."""
        self.x, Phi = self.flow(self.x, dt, force0, force1, control)
        self.P = Phi @ self.P @ Phi.T + self.Q

    def update(self, y: np.ndarray, present: np.ndarray, force: float,
               control: np.ndarray) -> None:
        """Measurement update with the rows ``present`` of y = [a1, a2, a3, φ], linearised at the
        predicted mean (:meth:`measurement`); the covariance in Joseph form, (I − K H) P (I − K H)ᵀ
        + K R Kᵀ."""
        h, H = self.measurement(self.x, force, control)
        H, R = H[present], self.R[np.ix_(present, present)]
        residual = (y - h)[present]
        PHt = self.P @ H.T
        K = np.linalg.solve(H @ PHt + R, PHt.T).T
        self.x = self.x + K @ residual
        I_KH = np.eye(self.x.size) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ R @ K.T
