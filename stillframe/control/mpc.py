"""Linear model predictive control of the pendulum torque (``controller.type: mpc``).

The prediction grid (:class:`PredictionGrid`) spans ``controller.horizon_s`` in N steps of h
samples each (at most ``controller.prediction_steps`` steps; h = 1 while the horizon has no more
samples than that, so at 32 Hz with the defaults N = 20, h = 1). On the LQG's design model
discretised with a zero-order hold at the grid step hT (x⁺ = A x + B u, the torque held over the
step, :func:`~stillframe.control.lqg.design_lqr`), each sample solves

    min  Σ_{k=1}^{N−1} x_kᵀ Q x_k + x_Nᵀ P x_N + Σ_{k=0}^{N−1} (R u_k² + R_Δ (u_k − u_{k−1})²)
         + (R + BᵀPB)(ρ s² + 10⁻³ ρ s)
    s.t. x_0 = ẑ,  |u_k| ≤ u_max,  |u_0 − u_prev| ≤ Δ_max,  |u_k − u_{k−1}| ≤ h Δ_max (k ≥ 1),
         |φ_k| ≤ φ_max + s (k = 1 … N),  s ≥ 0,

with Q, R the LQG's weights (``controller.state_weights``, ``input_weight``), P the grid's LQR
Riccati solution as terminal cost (so that without active limits the first move is that LQR's
−K ẑ for every N), u_max, Δ_max (per sample) and φ_max from
:class:`~stillframe.control.limits.CommandLimits`, R_Δ = ``controller.rate_weight``, ρ =
``controller.angle_penalty``. The first move is applied for one sample, so it may step by Δ_max;
a later one is a plan over h samples, in which the actuator may ramp by h Δ_max. The angle limit
is soft (a disturbance may push the pendulum past it; then the slack s pays for the excess
instead of the problem being infeasible), the torque and its rate are hard.

Why a grid coarser than the sample: the QP's size is that of the grid, not of the rate, and a
horizon long enough to stop the pendulum inside the angle limit (a fraction of a second) would
be hundreds of samples at 1 kHz. With the horizon in samples (20 at 1 kHz: 20 ms) every solve
at 1 kHz needed about 2000 iterations and fell back; on the grid it is the QP of 32 Hz again,
re-solved every sample from the previous solution (docs/controllers.md).

The unknowns are the deviations from the LQR's own plan, u_k = −K x_k + v_k (closed-loop
prediction, Rossiter, *Model-Based Predictive Control*, ch. 6): with the terminal cost P the cost
is x_0ᵀ P x_0 + (R + BᵀPB) Σ v_k² exactly, so the Hessian in v is a multiple of the identity
(R_Δ = 0) whatever the weights; in u it would have the condition number of the prediction, which
the thesis's cheap input weight makes hopeless for an ADMM solver. The states are eliminated
(N + 1 unknowns [v, s], a dense QP of 4N + 1 rows), and the constraint matrix and the Hessian do
not change from sample to sample: OSQP (Stellato et al. 2020, ``osqp`` on PyPI) is set up once,
and each sample updates q, l, u and warm-starts from the previous solution moved on by one
sample (by 1/h of a grid step, linearly between the grid's points). The first move u_0 is
applied (receding horizon). OSQP's own default tolerances (10⁻³) end the iterations; the
polished solution is then exact where the active set was found (the tests compare it with
independent solvers to 10⁻⁵).

A solve that does not end *solved* (iteration limit ``controller.max_iter``, numerical trouble,
primal infeasibility, which the hard limits cannot cause while the previous command is within
them) falls back to the anti-windup LQG command of the grid's model
(:class:`~stillframe.control.lqg.ConditionedLQGLaw`, within the torque and rate limits by
construction; the unconstrained MPC's own first move); ``fallbacks`` counts them, and
controller_node reports the count in ``/diagnostics``. ``solve_s`` keeps the solver's own time of
the last 10⁵ solves (``stillframe bench controllers`` prints its p50 and p99 against the period).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import osqp
import scipy.sparse as sp

from stillframe.control.limits import CommandLimits
from stillframe.control.lqg import ConditionedLQGLaw, LQRDesign
from stillframe.durations import Durations
from stillframe.errors import InputError

SOLVED = osqp.SolverStatus.OSQP_SOLVED
#: iterations per second of period when ``controller.max_iter`` is null (about 1.3 us each here
#: for N = 20: a quarter of the period at most), and the bounds of that default
ITERATIONS_PER_S, MIN_ITER, MAX_ITER = 2e5, 50, 4000


def iteration_limit(max_iter: int | None, period: float) -> int:
    """``controller.max_iter``, or the default derived from the period (deterministic: the same
    in every process, which the lock-step equality needs; a wall-clock limit would not be)."""
    if max_iter is not None:
        return max_iter
    return int(min(MAX_ITER, max(MIN_ITER, round(period * ITERATIONS_PER_S))))


#: OSQP checks whether it has converged every this many iterations (not 25: a warm-started
#: solve at 1 kHz ends after 30 to 40), so a solve takes at least this many
CHECK_EVERY = 10
#: :meth:`MPCLaw.least_solve_s` times this many solves and keeps the least
LEAST_OF = 5
#: OSQP settings: its default tolerances, checked every :data:`CHECK_EVERY` iterations,
#: polished solutions
SETTINGS = {"eps_abs": 1e-3, "eps_rel": 1e-3, "check_termination": CHECK_EVERY,
            "polishing": True, "verbose": False, "warm_starting": True}


@dataclass(frozen=True)
class PredictionGrid:
    """The prediction grid: ``steps`` steps of ``samples`` sample periods each, the torque held
    over each step."""

    samples: int
    steps: int

    @classmethod
    def of(cls, horizon_s: float, steps: int, period: float) -> PredictionGrid:
        """The grid of ``controller.horizon_s`` in at most ``controller.prediction_steps`` steps
        at the sample period ``period``: the horizon rounded to whole samples (at least one),
        then to whole steps of ⌈horizon samples / steps⌉ samples each."""
        horizon = max(1, round(horizon_s / period))
        samples = -(-horizon // steps)
        return cls(samples, -(-horizon // samples))


def prediction(A: np.ndarray, B: np.ndarray, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Φ (N n × n) and Γ (N n × N) with [x_1; …; x_N] = Φ x_0 + Γ [u_0; …; u_{N−1}]."""
    n = A.shape[0]
    powers = [np.eye(n)]
    for _ in range(horizon):
        powers.append(A @ powers[-1])
    Phi = np.vstack(powers[1:])
    Gamma = np.zeros((horizon * n, horizon))
    for k in range(horizon):                     # x_{k+1} = A^{k+1} x_0 + Σ_j A^{k−j} B u_j
        for j in range(k + 1):
            Gamma[k * n:(k + 1) * n, j] = powers[k - j] @ B[:, 0]
    return Phi, Gamma


class MPCLaw:
    """The receding-horizon command (module docstring); called like the other laws. ``design``
    is the LQR of the grid's model (:func:`~stillframe.control.lqg.design_lqr` at the grid's
    step), ``limits`` are those of one sample."""

    def __init__(self, design: LQRDesign, input_weight: float, *, limits: CommandLimits,
                 grid: PredictionGrid, angle_index: int, rate_weight: float = 0.0,
                 angle_penalty: float = 1e6, max_iter: int = 200) -> None:
        n = design.A.shape[0]
        N = grid.steps
        self.design, self.limits, self.grid = design, limits, grid
        self.fallback_law = ConditionedLQGLaw(design, False, limits, angle_index)
        K = design.gain
        B = design.B
        # closed-loop prediction: x_{k+1} = (A − BK) x_k + B v_k, u_k = −K x_k + v_k
        Phi, Gamma = prediction(design.A - B @ K, B, N)
        states_x = np.vstack([np.eye(n), Phi[:-n]])              # x_0 … x_{N−1} from x_0
        states_v = np.vstack([np.zeros((n, N)), Gamma[:-n]])     # … and from V
        KN = np.kron(np.eye(N), K)
        self._u_x, self._u_v = -KN @ states_x, np.eye(N) - KN @ states_v   # U = U_x x0 + U_v V
        scale = float(input_weight + B[:, 0] @ design.riccati @ B[:, 0])   # R + BᵀPB
        difference = np.eye(N) - np.eye(N, k=-1)
        DU = difference @ self._u_v
        hessian = scale * np.eye(N) + rate_weight * DU.T @ DU
        try:
            np.linalg.cholesky(hessian)
        except np.linalg.LinAlgError:
            raise InputError("controller.input_weight: the MPC's Hessian is not positive "
                             "definite (weights must make it so: input_weight > 0, "
                             "state_weights >= 0)") from None
        self.scale, self.rate_weight, self._difference = scale, rate_weight, difference
        P = np.zeros((N + 1, N + 1))
        P[:N, :N] = 2.0 * hessian / scale                        # the cost divided by R + BᵀPB
        P[N, N] = 2.0 * angle_penalty
        self._q = np.zeros(N + 1)
        self._q[N] = 1e-3 * angle_penalty
        # rows: u bounds (N), steps (N), angle upper (N), angle lower (N), slack >= 0 (1)
        rows = [np.hstack([self._u_v, np.zeros((N, 1))]), np.hstack([DU, np.zeros((N, 1))])]
        self._angle = None
        if limits.angle is not None:
            G = Gamma[angle_index::n]                           # φ_1 … φ_N from V
            self._angle = Phi[angle_index::n]
            rows += [np.hstack([G, -np.ones((N, 1))]), np.hstack([G, np.ones((N, 1))])]
        rows.append(np.eye(1, N + 1, N))
        A = np.vstack(rows)
        self._l = np.full(A.shape[0], -np.inf)
        self._u = np.full(A.shape[0], np.inf)
        self._l[-1] = 0.0
        self._bound_inputs(limits)
        if limits.step is not None:
            steps = np.full(N, limits.step * grid.samples)     # a ramp over one grid step …
            steps[0] = limits.step                              # … but u_0 within one sample
            self._l[N:2 * N], self._u[N:2 * N] = -steps, steps
        #: the QP ½ xᵀ P x + qᵀ x, l ≤ A x ≤ u as given to OSQP (q, l, u: :meth:`bounds`)
        self.qp_hessian, self.qp_matrix = P, A
        self.max_iter = max_iter
        self.solver = osqp.OSQP()
        self.solver.setup(sp.csc_matrix(np.triu(P)), self._q, sp.csc_matrix(A), self._l,
                          self._u, max_iter=max_iter, **SETTINGS)
        self.previous = 0.0
        self.fallbacks = 0
        self.solve_s = Durations()
        self.last: np.ndarray | None = None                     # the last solution (N + 1)
        self.dual: np.ndarray | None = None                     # … and its multipliers

    def _bound_inputs(self, limits: CommandLimits) -> None:
        """The QP's rows of u_0 … u_{N−1} bounded by ``limits.magnitude`` (unbounded: None)."""
        N = self.grid.steps
        bound = np.inf if limits.magnitude is None else limits.magnitude
        self._l[:N], self._u[:N] = -bound, bound

    def set_limits(self, limits: CommandLimits) -> None:
        """Plan with ``limits`` from the next call on (the controller's limit changed): the
        QP's input bounds, the clip of its answer and the fallback law's."""
        self.limits = limits
        self._bound_inputs(limits)
        self.fallback_law.set_limits(limits)

    def least_solve_s(self) -> float:
        """The least CPU time a solve of this QP takes here: :data:`CHECK_EVERY` iterations (or
        ``max_iter``, if fewer), measured on a solver of its own (this one keeps its cold
        start) that checks no termination (it does them all) and adapts no rho (no
        factorisation among the iterations measured), the least of :data:`LEAST_OF` solves: one
        solve can be slowed many times over by a page fault or a preemption it is charged for."""
        iterations = min(CHECK_EVERY, self.max_iter)
        probe = osqp.OSQP()
        q, lo, hi = self.bounds(np.zeros(self.design.A.shape[0]))
        probe.setup(sp.csc_matrix(np.triu(self.qp_hessian)), q, sp.csc_matrix(self.qp_matrix),
                    lo, hi, **{**SETTINGS, "check_termination": 0, "polishing": False,
                               "adaptive_rho": False, "max_iter": iterations})
        times = []
        for _ in range(LEAST_OF):
            started = time.thread_time()
            probe.solve(raise_error=False)
            times.append(time.thread_time() - started)
        return min(times)

    def inputs(self, z: np.ndarray, solution: np.ndarray) -> np.ndarray:
        """The planned commands u_0 … u_{N−1} of a QP solution [V, s] at the estimate z."""
        return self._u_x @ z + self._u_v @ solution[:self.grid.steps]

    def bounds(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, l, u of the QP at the estimate ``z`` and the previous command."""
        N = self.grid.steps
        q = self._q.copy()
        free_u = self._u_x @ z                                  # the LQR's plan: U at V = 0
        steps = self._difference @ free_u
        steps[0] -= self.previous                               # u_0 − u_prev
        q[:N] = 2.0 * self.rate_weight * (self._difference @ self._u_v).T @ steps / self.scale
        lo, hi = self._l.copy(), self._u.copy()
        lo[:N] -= free_u
        hi[:N] -= free_u
        lo[N:2 * N] -= steps
        hi[N:2 * N] -= steps
        if self._angle is not None:
            free = self._angle @ z
            hi[2 * N:3 * N] = self.limits.angle - free
            lo[3 * N:4 * N] = -self.limits.angle - free
        return q, lo, hi

    def __call__(self, z: np.ndarray, force: float) -> tuple[float, bool]:
        q, lo, hi = self.bounds(z)
        self.solver.update(q=q, l=lo, u=hi)
        if self.last is not None:
            v = self.last[:self.grid.steps]
            ahead = np.append(v[1:], 0.0)                       # the plan one grid step later
            f = 1.0 / self.grid.samples                         # … one sample later
            self.solver.warm_start(x=np.append((1.0 - f) * v + f * ahead, self.last[-1]))
        result = self.solver.solve(raise_error=False)
        self.solve_s.add(result.info.solve_time)
        if result.info.status_val != SOLVED.value:
            self.fallbacks += 1
            self.last = None
            self.fallback_law.previous = self.previous
            u, _ = self.fallback_law(z, force)
        else:
            self.last = np.asarray(result.x, dtype=float)
            self.dual = np.asarray(result.y, dtype=float)
            lo, hi = self.limits.actuator_interval(self.previous)
            u = min(max(float(self.inputs(z, self.last)[0]), lo), hi)  # the solver's tolerance
        self.previous = u
        return u, False
