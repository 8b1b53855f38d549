"""One sample period of the linear plant (``plant.model: file``) as one matrix product.

The plant E ẋ = A x + B u(t) (:class:`~stillframe.dynamics.systems.LinearSystem`) is advanced
by s substeps of h = period / s with the actuator command u_c held. Each substep is an affine
recurrence

    x_{j+1} = M x_j + N u_c + Σ_taps L_c f(t_j + c h),

f the excitation force on its floor, so the states after 1..s substeps are linear in
z = [x_0, u_c, f at the tap times of the period] and one product Y = W z gives the truth the
plant records at every substep and the state at the period's end. W is built once.

Two discretisations of a substep (``plant.discretization``):

- ``substeps``: the implicit midpoint rule of :class:`~stillframe.dynamics.integrators.
  ImplicitMidpoint`, (E − h/2 A) x_{j+1} = (E + h/2 A) x_j + h B u(t_j + h/2), so M and N are
  the solves of that matrix; the same numbers as stepping the integrator, to round-off.
- ``zoh``: exact for the held command (zero-order hold) and for a force linear between the
  substep times (first-order hold): Φ = e^{A_e h}, Γ0, Γ1 of
  :func:`stillframe.design.discrete.first_order_hold` on A_e = E⁻¹A, B_e = E⁻¹B, so
  x_{j+1} = Φ x_j + Γ0 u_c + (Γ0 − Γ1) f(t_j) + Γ1 f(t_{j+1}). The free and the commanded
  response are exact at any h; only the force's curvature within a substep is approximated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from stillframe.design.discrete import first_order_hold
from stillframe.dynamics.excitation import FloorLoad
from stillframe.dynamics.systems import LinearSystem

#: periods whose excitation force is evaluated at once
CHUNK = 64


@dataclass(frozen=True)
class Recurrence:
    """x_{j+1} = M x_j + N u_c + Σ L f(t_j + c h) over (c, L) in ``taps``; L is n×4 (the
    columns of u = [f1, f2, f3, torque])."""

    M: np.ndarray
    N: np.ndarray
    taps: tuple[tuple[float, np.ndarray], ...]


def midpoint_recurrence(system: LinearSystem, h: float) -> Recurrence:
    """The implicit midpoint substep (module docstring)."""
    lu = sla.lu_factor(system.E - 0.5 * h * system.A, check_finite=False)
    M = sla.lu_solve(lu, system.E + 0.5 * h * system.A)
    N = sla.lu_solve(lu, h * system.B)
    return Recurrence(M, N, ((0.5, N),))


def zoh_recurrence(system: LinearSystem, h: float) -> Recurrence:
    """The exact substep for a held command and a force linear over the substep."""
    lu = sla.lu_factor(system.E, check_finite=False)
    d = first_order_hold(sla.lu_solve(lu, system.A), sla.lu_solve(lu, system.B), h)
    return Recurrence(d.phi, d.gamma0, ((0.0, d.gamma0 - d.gamma1), (1.0, d.gamma1)))


class LinearPeriod:
    """The substeps of one period of a linear plant, as ``step`` → (recorded rows, end state).

    ``recorded`` are the indices of the state the plant records at every substep."""

    def __init__(self, system: LinearSystem, load: FloorLoad | None, recurrence: Recurrence,
                 period: float, substeps: int, recorded: np.ndarray) -> None:
        self.load = load
        self.period = period
        self.h = period / substeps
        self.substeps = substeps
        n, r = system.n, len(recorded)
        offsets = sorted({j + c for j in range(substeps) for c, _ in recurrence.taps})
        column: dict[float, int] = {o: n + 4 + i for i, o in enumerate(offsets)}
        taps = [(c, L[:, load.excitation.floor - 1]) for c, L in recurrence.taps] if load else []
        self.offsets = np.array(offsets)
        state = np.hstack([np.eye(n), np.zeros((n, 4 + len(offsets)))])
        rows = []
        for j in range(substeps):
            state = recurrence.M @ state
            state[:, n : n + 4] += recurrence.N
            for c, column_of_load in taps:
                state[:, column[j + c]] += column_of_load
            rows.append(state[recorded])
        self.W = np.vstack([*rows, state])
        self.n, self.n_recorded = n, r
        self.z = np.zeros(self.W.shape[1])
        self._forces = np.empty((0, len(offsets)))
        self._first = 0     # the period of the first row of _forces

    def forces(self, k: int) -> np.ndarray:
        """The force at the tap times of period k, t_k + offsets · h with t_k = k · period,
        evaluated :data:`CHUNK` periods at a time (the same numbers as one at a time)."""
        if not self._first <= k < self._first + len(self._forces):
            assert self.load is not None
            self._first = k - k % CHUNK
            t0 = np.arange(self._first, self._first + CHUNK)[:, None] * self.period
            self._forces = self.load.force_at(t0 + self.offsets * self.h)
        return self._forces[k - self._first]

    def step(self, x: np.ndarray, k: int, control: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The recorded values after each substep (substeps × recorded) and the end state,
        from x at the start of period k with the inputs ``control`` = u_c held."""
        n, z = self.n, self.z
        z[:n] = x
        z[n : n + 4] = control
        if self.load is not None:
            z[n + 4 :] = self.forces(k)
        y = self.W @ z
        rows = self.substeps * self.n_recorded
        return y[:rows].reshape(self.substeps, self.n_recorded), y[rows:]


def make_linear_period(system: LinearSystem, load: FloorLoad | None, discretization: str,
                       period: float, substeps: int, recorded: np.ndarray) -> LinearPeriod:
    """The period stepper of ``plant.discretization`` for ``system`` under ``load``."""
    h = period / substeps
    recurrence = (zoh_recurrence if discretization == "zoh" else midpoint_recurrence)(system, h)
    return LinearPeriod(system, load, recurrence, period, substeps, recorded)
