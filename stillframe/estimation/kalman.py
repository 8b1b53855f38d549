"""Kalman filters on a linear design model (thesis §4.4, §5.6).

Model: the design model linearised at rest (eq. 5.59–5.66) or an identified structure with the
pendulum (eq. 5.199–5.207), discretised at the sample period with the command held and the
measured excitation linear between load-cell samples (:mod:`stillframe.design.discrete`). The
measurements are the floor accelerations and φ (eq. 5.209–5.212): y = C z + D u with C, D the
acceleration rows of the continuous state equation. Process noise: discrete, per sample.

- :class:`SteadyStateKalman`: the stationary filter. Its a-priori covariance P∞ solves the
  discrete Riccati equation (:func:`stillframe.design.riccati.solve_dare`: scipy's solver after PBH
  checks; filterpy has no stationary filter); the gain for the channels present is
  P∞ Cₛᵀ (Cₛ P∞ Cₛᵀ + Rₛ)⁻¹, the stationary gain when all arrive. After a gap (an interval
  longer than the period) the mean is propagated over the true interval but the covariance
  stays P∞. Started from one sample (an estimator joining a running loop), it propagates its
  covariance as the time-varying filter does until that reaches P∞.
- :class:`TimeVaryingKalman`: filterpy's ``KalmanFilter`` (predict with our input matrices,
  update with the rows present).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from stillframe.config.loop_sections import Estimator
from stillframe.contract.signals import Estimate, Sample, full_inputs
from stillframe.design.discrete import Discrete, first_order_hold
from stillframe.design.riccati import solve_dare
from stillframe.dynamics.models import FrameModel
from stillframe.estimation.base import Filter

__all__ = ["CONVERGED", "LinearFilter", "SteadyStateKalman", "TimeVaryingKalman"]

CONVERGED = 1e-6
"""A stationary filter started from one sample takes P∞ once its propagated prior is this close
to it (relative, Frobenius norm): the gains then differ by about as much."""


class LinearFilter(Filter):
    """Shared linear model: Φ, Γ0, Γ1 per interval length, and y = C z + D u."""

    def __init__(self, model: FrameModel, config: Estimator, excited_floor: int,
                 initial_physical: np.ndarray, period: float) -> None:
        super().__init__(model, config, excited_floor, initial_physical)
        self.A, self.B = model.linearized().state_space()
        n = model.n_dof
        rows = [n + i for i in model.floor_index]
        self.C = np.vstack([self.A[rows], np.eye(2 * n)[model.phi_index]])
        self.D = np.vstack([self.B[rows], np.zeros((1, 4))])
        self.period = period
        self.restart_velocity_std = config.restart_velocity_std
        self._discrete: dict[float, Discrete] = {}

    def discrete(self, dt: float) -> Discrete:
        """Φ, Γ0 and Γ1 of :func:`~stillframe.design.discrete.first_order_hold` over an interval of
        ``dt`` [s], computed once per interval length."""
        key = round(dt, 12)
        if key not in self._discrete:
            self._discrete[key] = first_order_hold(self.A, self.B, dt)
        return self._discrete[key]

    def propagate_mean(self, dt: float, force0: float, force1: float,
                       control: np.ndarray) -> Discrete:
        """Advance the mean over ``dt`` [s]: the excitation linear from ``force0`` to ``force1`` [N]
        and ``control`` held; returns the discretization used, for the covariance."""
        d = self.discrete(dt)
        u0 = full_inputs(control, force0, self.excited_floor)
        u1 = full_inputs(control, force1, self.excited_floor)
        self.x = d.phi @ self.x + d.gamma0 @ u0 + d.gamma1 @ (u1 - u0)
        return d

    def initialise_from(self, sample: Sample, control: np.ndarray) -> Estimate:
        """Start from one sample, in place of :meth:`step` for it (an estimator that joins a
        running loop); returns the estimate at the sample.

        The mean: φ from the encoder, the floor displacements that explain the measured
        accelerations with the model's y = C z + D u (the sample's excitation and ``control`` as
        inputs), the velocities zero. The covariance: the velocities' is
        ``estimator.restart_velocity_std`` (one sample does not measure them); the
        displacements' is what the measurement noise R and the velocities (through the damping
        terms of the acceleration rows, which the mean takes as zero) give them through the
        same map. The sample is used once: the next one is predicted from it."""
        force = float(sample.force) if np.isfinite(sample.force) else 0.0
        u = full_inputs(control, force, self.excited_floor)
        read = np.asarray(sample.measurements, dtype=float) - self.D @ u
        accelerations = self.C[:3] @ self.T        # per physical state
        floors = np.linalg.pinv(accelerations[:, :3])
        # the physical state = M [y − D u, v] for the velocities v, taken as zero in the mean
        M = np.eye(8)
        M[:3, :3] = floors
        M[:3, 3] = -floors @ accelerations[:, 3]
        M[:3, 4:] = -floors @ accelerations[:, 4:]
        physical = M[:, :4] @ read
        spread = M @ sla.block_diag(self.R, np.diag(np.square(self.restart_velocity_std))) @ M.T
        self.x, self.P = self.T @ physical, self.T @ spread @ self.T.T
        self.t, self.force = sample.t, force
        self.counters.updates += 1
        return self.estimate()

    def innovation(self, y: np.ndarray, present: np.ndarray, force: float,
                   control: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Measured minus feedthrough, and the C and R rows of the channels present."""
        u = full_inputs(control, force, self.excited_floor)
        if present.all():
            return y - self.D @ u, self.C, self.R
        return (y - self.D @ u)[present], self.C[present], self.R[np.ix_(present, present)]


class SteadyStateKalman(LinearFilter):
    """Stationary Kalman filter (fixed covariance P∞ at the nominal period).

    Started from one sample (:meth:`LinearFilter.initialise_from`), its covariance is far from
    P∞: it is propagated and updated as a time-varying filter's until its prior is within
    :data:`CONVERGED` of P∞ (relative, Frobenius norm), and is P∞ from there on."""

    def __init__(self, model: FrameModel, config: Estimator, excited_floor: int,
                 initial_physical: np.ndarray, period: float) -> None:
        super().__init__(model, config, excited_floor, initial_physical, period)
        self.design(self.Q, self.R)
        self.P = self.prior
        self.converging = False

    def design(self, Q: np.ndarray, R: np.ndarray) -> None:
        """P∞ and the full gain for Q, R (InputError, nothing changed, if the DARE fails)."""
        d = self.discrete(self.period)
        self.prior = solve_dare(d.phi.T, self.C.T, Q, R,
                                what="stationary Kalman filter (dual Riccati equation)")
        self.Q, self.R = Q, R
        self.gain = self.gain_for(np.ones(4, dtype=bool))
        self.posterior = self.prior - self.gain @ self.C @ self.prior  # all channels present

    def set_noise(self, process_std: list[float], measurement_std: list[float]) -> None:
        """Design P∞ and the gains again for the new standard deviations (:meth:`design`)."""
        self.design(*self.noise_covariances(process_std, measurement_std))

    def initialise_from(self, sample: Sample, control: np.ndarray) -> Estimate:
        """Start from one sample (:meth:`LinearFilter.initialise_from`); the covariance converges
        to P∞ from the one the sample gives."""
        self.converging = True
        return super().initialise_from(sample, control)

    def _extra_state(self) -> bool:
        """Whether the covariance is still converging to P∞."""
        return self.converging

    def _restore_extra(self, extra: bool) -> None:
        self.converging = extra

    def gain_for(self, present: np.ndarray, prior: np.ndarray | None = None) -> np.ndarray:
        """The gain P Cₛᵀ (Cₛ P Cₛᵀ + Rₛ)⁻¹ for the rows ``present`` of y; P is ``prior``, by
        default P∞."""
        P = self.prior if prior is None else prior
        C, R = self.C[present], self.R[np.ix_(present, present)]
        return sla.solve(C @ P @ C.T + R, C @ P, assume_a="pos").T

    def predict(self, dt: float, force0: float, force1: float, control: np.ndarray) -> None:
        """Propagate the mean over ``dt`` [s]; the covariance stays the stationary prior P∞, or,
        while it converges, is propagated (Φ P Φᵀ + Q)."""
        d = self.propagate_mean(dt, force0, force1, control)
        if not self.converging:
            self.P = self.prior
            return
        P = d.phi @ self.P @ d.phi.T + self.Q
        if np.linalg.norm(P - self.prior) <= CONVERGED * np.linalg.norm(self.prior):
            self.converging, P = False, self.prior
        self.P = P

    def update(self, y: np.ndarray, present: np.ndarray, force: float,
               control: np.ndarray) -> None:
        """Correct the mean with the measurement rows ``present``: the stationary gain when all are
        present, else the gain for those rows (:meth:`gain_for`) and the posterior covariance it
        gives; while the covariance converges, the gain of the propagated one (Joseph form)."""
        z, C, R = self.innovation(y, present, force, control)
        if self.converging:
            K = self.gain_for(present, self.P)
            self.x = self.x + K @ (z - C @ self.x)
            keep = np.eye(self.x.size) - K @ C
            self.P = keep @ self.P @ keep.T + K @ R @ K.T
            return
        if present.all():
            self.x = self.x + self.gain @ (z - C @ self.x)
            self.P = self.posterior
            return
        K = self.gain_for(present)
        self.x = self.x + K @ (z - C @ self.x)
        self.P = self.prior - K @ C @ self.prior


class TimeVaryingKalman(LinearFilter):
    """Kalman filter with the covariance propagated every sample (filterpy ``KalmanFilter``)."""

    def __init__(self, model: FrameModel, config: Estimator, excited_floor: int,
                 initial_physical: np.ndarray, period: float) -> None:
        super().__init__(model, config, excited_floor, initial_physical, period)
        # imported where the filter is built, before any loop runs: filterpy imports scipy.stats,
        # which costs every node process a second of start-up that only this filter needs
        from filterpy.kalman import KalmanFilter

        self.kf = KalmanFilter(dim_x=self.x.size, dim_z=4)
        self.kf.x, self.kf.P, self.kf.Q, self.kf.R = self.x, self.P, self.Q, self.R

    def set_noise(self, process_std: list[float], measurement_std: list[float]) -> None:
        """New Q and R for the filter and for filterpy's ``KalmanFilter`` inside it."""
        super().set_noise(process_std, measurement_std)
        self.kf.Q, self.kf.R = self.Q, self.R

    def initialise_from(self, sample: Sample, control: np.ndarray) -> Estimate:
        """Start from one sample (:meth:`LinearFilter.initialise_from`), filterpy's filter taking
        the mean and covariance too."""
        estimate = super().initialise_from(sample, control)
        self.kf.x, self.kf.P = self.x, self.P
        return estimate

    def continue_from(self, previous: Filter) -> None:
        """Go on from ``previous`` (:meth:`Filter.continue_from`), filterpy's filter taking the
        mapped mean too."""
        super().continue_from(previous)
        self.kf.x = self.x

    def _restore_extra(self, extra: None) -> None:
        """filterpy's filter takes the restored mean and covariance."""
        self.kf.x, self.kf.P = self.x, self.P

    def predict(self, dt: float, force0: float, force1: float, control: np.ndarray) -> None:
        """filterpy's predict with Φ and the inputs [u0, u1 − u0] through [Γ0, Γ1] over ``dt``
        [s]."""
        d = self.discrete(dt)
        u0 = full_inputs(control, force0, self.excited_floor)
        u1 = full_inputs(control, force1, self.excited_floor)
        self.kf.predict(u=np.concatenate([u0, u1 - u0]), B=np.hstack([d.gamma0, d.gamma1]),
                        F=d.phi)
        self.x, self.P = self.kf.x, self.kf.P

    def update(self, y: np.ndarray, present: np.ndarray, force: float,
               control: np.ndarray) -> None:
        """filterpy's update with the rows ``present`` of y, their C and R."""
        z, C, R = self.innovation(y, present, force, control)
        self.kf.update(z, R=R, H=C)
        self.x, self.P = self.kf.x, self.kf.P
