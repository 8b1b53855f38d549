"""Structure-preserving time integration of the index-2 pHDAE: the implicit midpoint rule with an
averaged-vector-field (AVF) discrete gradient.

One step from (t₀, e₀) to (t₁, e₁) solves, for e₁ and the mean multipliers λ,

    E (e₁ − e₀) = h [(J(ē) − R(q̄)) z̄ + Ḡ λ + B(q̄) ū],     Ḡᵀ z̄ + ḡ_t = 0,

with ē the midpoint, z̄ = ∫₀¹ z(e₀ + s(e₁ − e₀)) ds (exact for the quadratic parts, Gauss–Legendre
for gravity) and Ḡ = [0; (∫₀¹ ∂g/∂q ds · A(q̄))ᵀ; 0]. Since Eᵀz = ∂H/∂e and J is skew,

    H(e₁) − H(e₀) = z̄ᵀ E (e₁ − e₀) = h (ȳᵀū − z̄ᵀRz̄ − λᵀḡ_t),

the discrete power balance, and g(q₁, t₁) − g(q₀, t₀) = h(∂ḡ/∂q A(q̄) ν̄ + ḡ_t) = 0: the
velocity-level constraints are met in a way that also keeps the position-level constraints
(no drift beyond the Newton tolerance and the quadrature's round-off). Newton with a
finite-difference Jacobian, reused across steps while it converges.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from stillframe.dynamics.ph.system import PHSystem
from stillframe.errors import InputError, IntegrationError

__all__ = ["AVF_POINTS", "InputSignal", "MidpointDAE", "StepRecord", "balance_error"]

AVF_POINTS = 4
NEWTON_TOL = 1e-13
MAX_ITER = 30

_S, _W = np.polynomial.legendre.leggauss(AVF_POINTS)
_S, _W = 0.5 * (_S + 1.0), 0.5 * _W

InputSignal = Callable[[float], np.ndarray]


@dataclass
class StepRecord:
    """Per-step balance terms: ΔH and h(ȳᵀū), h z̄ᵀRz̄, h λᵀḡ_t."""

    delta_h: list[float] = field(default_factory=list)
    supplied: list[float] = field(default_factory=list)
    dissipated: list[float] = field(default_factory=list)
    constraint_work: list[float] = field(default_factory=list)

    def residuals(self) -> np.ndarray:
        """ΔH − h(ȳᵀū − z̄ᵀRz̄ − λᵀḡ_t) per step."""
        return (np.asarray(self.delta_h) - np.asarray(self.supplied)
                + np.asarray(self.dissipated) + np.asarray(self.constraint_work))


class MidpointDAE:
    """The AVF implicit midpoint integrator of a :class:`PHSystem`."""

    name = "midpoint (AVF, pHDAE)"

    def __init__(self, system: PHSystem, dt: float, inputs: InputSignal | None = None) -> None:
        if dt <= 0:
            raise InputError(f"time step must be > 0, got {dt}")
        self.system = system
        self.dt = dt
        self.inputs = inputs
        self._lu: tuple | None = None

    def _averages(self, q0: np.ndarray, q1: np.ndarray, t0: float,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sys, h = self.system, self.dt
        grad = np.zeros(sys.n_q)
        Dg = np.zeros((sys.n_constraints, sys.n_q))
        rate = np.zeros(sys.n_constraints)
        for s, w in zip(_S, _W, strict=True):
            qs = q0 + s * (q1 - q0)
            grad += w * sys.potential_gradient(qs)
            if sys.n_constraints:
                _, d, r = sys.constraints(qs, t0 + s * h)
                Dg += w * d
                rate += w * r
        return grad, Dg, rate

    def _input(self, t: float) -> np.ndarray:
        if self.inputs is None:
            return np.zeros(len(self.system.inputs))
        return np.asarray(self.inputs(t), dtype=float)

    def residual(self, x: np.ndarray, e0: np.ndarray, t0: float) -> np.ndarray:
        sys, h, n = self.system, self.dt, self.system.n
        e1, lam = x[:n], x[n:]
        em = 0.5 * (e0 + e1)
        q0, q1 = e0[:sys.n_q], e1[:sys.n_q]
        qm, num, sm = sys.split(em)
        grad, Dg, rate = self._averages(q0, q1, t0)
        zbar = np.concatenate([grad, num, sm])
        A = sys.kinematics(qm)
        flow = (sys.interconnection(em) @ zbar)
        nq = sys.n_q
        flow[nq:2 * nq] -= sys.dissipation(qm) @ num
        if sys.n_constraints:
            flow[nq:2 * nq] += (Dg @ A).T @ lam
        if sys.inputs:
            flow[nq:2 * nq] += sys.input_matrix(qm) @ self._input(t0 + 0.5 * h)
        r1 = sys.descriptor @ (e1 - e0) - h * flow
        r2 = Dg @ A @ num + rate
        return np.concatenate([r1, r2])

    def _factor(self, x: np.ndarray, e0: np.ndarray, t0: float) -> None:
        jac = np.empty((x.size, x.size))
        for i in range(x.size):  # central differences: Newton converges quadratically
            step = 1e-6 * max(1.0, abs(x[i]))
            xp, xm = x.copy(), x.copy()
            xp[i] += step
            xm[i] -= step
            jac[:, i] = (self.residual(xp, e0, t0) - self.residual(xm, e0, t0)) / (2 * step)
        self._lu = sla.lu_factor(jac)

    def step(self, e0: np.ndarray, lam0: np.ndarray, t0: float,
             guess: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One step; returns e₁ and the step's mean multipliers λ (Newton from ``guess`` of e₁,
        default e₀)."""
        x = np.concatenate([e0 if guess is None else guess, lam0])
        if self._lu is None:
            self._factor(x, e0, t0)
        previous = np.inf
        for _ in range(MAX_ITER):
            delta = sla.lu_solve(self._lu, self.residual(x, e0, t0))
            x = x - delta
            size = np.max(np.abs(delta)) / max(1.0, np.max(np.abs(x)))
            if not np.isfinite(size):
                break
            if size < NEWTON_TOL or (size < 1e-10 and size >= 0.5 * previous):
                return x[:self.system.n], x[self.system.n:]
            if size > 0.25 * previous:  # slow contraction: a fresh Jacobian (full Newton)
                self._factor(x, e0, t0)
            previous = size
        raise IntegrationError(f"implicit midpoint: Newton did not converge at t = {t0:.6g} s; "
                         "reduce the time step")

    def run(self, e0: np.ndarray, t_end: float, t0: float = 0.0,
            every: int = 1, progress: Callable[[float], None] | None = None,
            ) -> tuple[np.ndarray, np.ndarray, StepRecord, np.ndarray]:
        """Integrate to t_end; returns times, states (every ``every`` steps), the per-step
        balance record and the largest position-constraint residual per stored state (the
        final state is always stored)."""
        sys, h = self.system, self.dt
        steps = round((t_end - t0) / h)
        lam = np.zeros(sys.n_constraints)
        e = np.array(e0, dtype=float)
        times, states, drift = [t0], [e.copy()], [self._drift(e, t0)]
        record = StepRecord()
        H0 = sys.hamiltonian(e)
        previous = e
        for k in range(steps):
            t = t0 + k * h
            e1, lam = self.step(e, lam, t, guess=2 * e - previous if k else None)
            previous = e
            if not np.all(np.isfinite(e1)):
                raise IntegrationError(f"implicit midpoint: non-finite state at t = {t:.6g} s")
            H1 = sys.hamiltonian(e1)
            em = 0.5 * (e + e1)
            _, _, rate = self._averages(e[:sys.n_q], e1[:sys.n_q], t)
            u = self._input(t + 0.5 * h)
            qm, num, _ = sys.split(em)
            record.delta_h.append(H1 - H0)
            record.supplied.append(h * float(sys.input_matrix(qm).T @ num @ u)
                                   if sys.inputs else 0.0)
            record.dissipated.append(h * float(num @ sys.dissipation(qm) @ num))
            record.constraint_work.append(h * float(lam @ rate))
            e, H0 = e1, H1
            if (k + 1) % every == 0 or k == steps - 1:
                times.append(t + h)
                states.append(e.copy())
                drift.append(self._drift(e, t + h))
                if progress is not None:
                    progress(t + h)
        return np.asarray(times), np.asarray(states), record, np.asarray(drift)

    def _drift(self, e: np.ndarray, t: float) -> float:
        g = self.system.constraints(e[:self.system.n_q], t)[0]
        return float(np.max(np.abs(g))) if g.size else 0.0


def balance_error(record: StepRecord, energies_scale: float) -> float:
    """Largest |ΔH − h(ȳᵀū − z̄ᵀRz̄ − λᵀḡ_t)| over the run, relative to ``energies_scale``."""
    res = record.residuals()
    return float(np.max(np.abs(res)) / energies_scale) if res.size else 0.0
