"""Compiled (numba) time stepping of a :class:`~stillframe.dynamics.models.FrameModel` under its
own loads.

The same equations as :class:`~stillframe.dynamics.systems.MechanicalSystem` with the same schemes
as
:mod:`stillframe.dynamics.integrators`, without Python overhead per step:

- ``rk4``: classical RK4 on q̈ = M(q)⁻¹Q (the Schur-complement solve of
  :meth:`FrameModel.accelerations`), dense structural matrices — for the lumped and modal models.
- ``midpoint``: the implicit midpoint rule E(x_m)(x₁ − x₀) = h f(t_m, x_m) solved exactly in
  the unknown v_m = (v₀ + v₁)/2. With q_m = q₀ + (h/2) v_m the structural rows are linear:

      (2 M_c + h C + (h²/2) K) v_m,s = 2 M_c v₀,s − h K q₀,s + h f_s(t_m) + σ e₃,
      σ = h m₄L₄ sin φ_m p² − 2 m₄L₄ cos φ_m (p − φ̇₀),   p = φ̇_m,

  so v_m,s = y + σ w with y = S⁻¹(…) and w = S⁻¹e₃, and the pendulum row (thesis eq. 5.57 in φ)
  leaves one scalar equation in p, solved by Newton. S is banded once the DOFs are ordered by
  height (reverse Cuthill–McKee) except for the rank-r modal part of C
  (:class:`~stillframe.dynamics.models.structure.DampingParts`), handled by the Woodbury identity:
  one step costs O(n (b + r)) for half-bandwidth b — linear in the number of DOFs.

Loads: none, harmonics, hammer and chirp on one floor, plus a control input held over the run.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np
import scipy.linalg as sla
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import reverse_cuthill_mckee

from stillframe.dynamics.excitation import FloorLoad
from stillframe.dynamics.integrators import Subdivision, floor_failure
from stillframe.dynamics.models.frame import FrameModel
from stillframe.dynamics.models.structure import DampingParts
from stillframe.errors import IntegrationError

COMPILED_METHODS = ("rk4", "midpoint")
_LOAD_KIND = {"none": 0, "harmonics": 1, "hammer": 2, "chirp": 3}
#: the midpoint kernel's scalar Newton iteration on the pendulum row: relative step tolerance and
#: iteration limit (numba folds both into the compiled code)
NEWTON_TOL = 1e-14
NEWTON_MAX_ITER = 50


# --- loads ---------------------------------------------------------------------------------------
@numba.njit(cache=True)
def _force(t: float, kind: int, amps: np.ndarray, omegas: np.ndarray, phases: np.ndarray,
           pulse: np.ndarray) -> float:
    """The excitation force at t (:mod:`stillframe.dynamics.excitation`): harmonics, hammer or
    chirp."""
    if kind == 1:
        s = 0.0
        for i in range(amps.size):
            s += amps[i] * math.sin(omegas[i] * t + phases[i])
        return s
    if kind == 2:  # pulse = (peak, time, width)
        s = t - pulse[1]
        if 0.0 <= s <= pulse[2]:
            return pulse[0] * math.sin(math.pi * s / pulse[2])
        return 0.0
    if kind == 3:  # pulse = (amplitude, f0, rate, sweep)
        if 0.0 <= t <= pulse[3]:
            return pulse[0] * math.sin(2.0 * math.pi * (pulse[1] * t + 0.5 * pulse[2] * t * t))
        return 0.0
    return 0.0


def load_arrays(load: FloorLoad | None) -> tuple | None:
    """(kind, floor, amps, omegas, phases, pulse) for the kernels, or None if not compilable."""
    empty = np.zeros(0)
    if load is None:
        return 0, 0, empty, empty, empty, np.zeros(4)
    if not isinstance(load, FloorLoad) or load.excitation.type not in _LOAD_KIND:
        return None
    e = load.excitation
    kind = _LOAD_KIND[e.type]
    amps, omegas, phases, pulse = empty, empty, empty, np.zeros(4)
    if e.type == "harmonics":
        amps = np.asarray(e.amplitudes, float)
        omegas = 2.0 * np.pi * np.asarray(e.frequencies_hz, float)
        phases = np.asarray(e.phases, float) if e.phases else np.zeros(amps.size)
    elif e.type == "hammer":
        pulse = np.array([np.pi * e.impulse / (2.0 * e.width), e.time, e.width, 0.0])
    elif e.type == "chirp":
        pulse = np.array([e.amplitude, e.f0_hz, (e.f1_hz - e.f0_hz) / e.sweep_s, e.sweep_s])
    return kind, e.floor - 1, amps, omegas, phases, pulse


# --- RK4 on the dense model ----------------------------------------------------------------------
@numba.njit(cache=True)
def _accelerations(x, u, f_ext, floor_index, i3, K, C, Minv, w, p, Q, out):
    """FrameModel.accelerations: q̈ = M(q)⁻¹Q by the Schur complement of the pendulum row.

    ``x = [q, v]`` (q and v of length n + 1, the pendulum last); q̈ goes to ``out[n + 1:]`` and
    ``Q`` is scratch space of length n (no allocation in the hot loop).
    """
    n = K.shape[0]
    nd = n + 1
    m4, l4, g, r4, J = p[0], p[1], p[2], p[3], p[4]
    phi, dphi = x[n], x[nd + n]
    sin_phi = math.sin(phi)
    for i in range(n):
        s = 0.0
        for j in range(n):
            s -= K[i, j] * x[j] + C[i, j] * x[nd + j]
        Q[i] = s
    for k in range(3):
        Q[floor_index[k]] += u[k] + f_ext[k]
    Q[i3] += m4 * l4 * sin_phi * dphi * dphi
    q_phi = u[3] - m4 * g * l4 * sin_phi - r4 * dphi
    c = m4 * l4 * math.cos(phi)
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += Minv[i, j] * Q[j]
        out[nd + i] = s
    a_phi = (q_phi - c * out[nd + i3]) / (J - c * c * w[i3])
    for i in range(n):
        out[nd + i] -= c * a_phi * w[i]
    out[nd + n] = a_phi


@numba.njit(cache=True, inline="always")
def _stage(x, a, k, out):
    """out = x + a k."""
    for i in range(x.size):
        out[i] = x[i] + a * k[i]


@numba.njit(cache=True, inline="always")
def _derivative(x, u, f_ext, floor_index, i3, K, C, Minv, w, p, Q, out):
    """ẋ = [v, q̈] of the state x = [q, v]."""
    nd = K.shape[0] + 1
    for i in range(nd):
        out[i] = x[nd + i]
    _accelerations(x, u, f_ext, floor_index, i3, K, C, Minv, w, p, Q, out)


@numba.njit(cache=True)
def _rk4_run(x, t0, h, k0, n_steps, stride, out, error_limit, floor_index, i3, K, C, Minv, w, p,
             u, load_kind, load_floor, amps, omegas, phases, pulse):
    """Advance steps k0 … n_steps − 1 of RK4 from x (in place; step k starts at t0 + k h); the
    state after step k goes to ``out[(k + 1) // stride]`` when ``stride`` divides k + 1.

    With ``error_limit`` ≥ 0 each step is checked by the embedded third-order estimate
    (h/6)|k₄ − k₅|, k₅ = f(t + h, x₁), against error_limit · (1 + |x₁|); k₅ is reused as the next
    step's k₁ (first same as last: the same numbers as computing it afresh).

    Returns (k, status): status 0 when all steps are done (k = n_steps); otherwise k is the step
    that failed, x is still its starting state, and status is 1 (error estimate too large) or 2
    (non-finite result).
    """
    nd = K.shape[0] + 1
    m = 2 * nd
    k1 = np.empty(m)
    k2 = np.empty(m)
    k3 = np.empty(m)
    k4 = np.empty(m)
    k5 = np.empty(m)
    xs = np.empty(m)
    x1 = np.empty(m)
    scratch = np.empty(K.shape[0])
    f_ext = np.zeros(3)
    f_end = _force(t0 + k0 * h, load_kind, amps, omegas, phases, pulse)
    half = 0.5 * h
    checked = error_limit >= 0.0
    have_k1 = False
    for k in range(k0, n_steps):
        t = t0 + k * h
        # the load at t, t + h/2 (stages 2 and 3) and t + h (reused as the next step's start)
        f_start = f_end
        f_mid = _force(t + half, load_kind, amps, omegas, phases, pulse)
        f_end = _force(t + h, load_kind, amps, omegas, phases, pulse)
        f_ext[load_floor] = f_start
        if have_k1:
            for i in range(m):
                k1[i] = k5[i]
        else:
            _derivative(x, u, f_ext, floor_index, i3, K, C, Minv, w, p, scratch, k1)
        f_ext[load_floor] = f_mid
        _stage(x, half, k1, xs)
        _derivative(xs, u, f_ext, floor_index, i3, K, C, Minv, w, p, scratch, k2)
        _stage(x, half, k2, xs)
        _derivative(xs, u, f_ext, floor_index, i3, K, C, Minv, w, p, scratch, k3)
        f_ext[load_floor] = f_end
        _stage(x, h, k3, xs)
        _derivative(xs, u, f_ext, floor_index, i3, K, C, Minv, w, p, scratch, k4)
        finite = True
        for i in range(m):
            x1[i] = x[i] + (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            if not math.isfinite(x1[i]):
                finite = False
        if not finite:
            return k, 2
        if checked:
            _derivative(x1, u, f_ext, floor_index, i3, K, C, Minv, w, p, scratch, k5)
            for i in range(m):
                if (h / 6.0) * abs(k4[i] - k5[i]) > error_limit * (1.0 + abs(x1[i])):
                    return k, 1
            have_k1 = True
        for i in range(m):
            x[i] = x1[i]
        if (k + 1) % stride == 0:
            out[(k + 1) // stride, :] = x
    return n_steps, 0


# --- implicit midpoint on the banded model -------------------------------------------------------
@numba.njit(cache=True)
def _band_matvec(A, b, x, out):
    """out = A x for A stored by diagonals: A[i, b + j − i] = A_ij, |i − j| ≤ b."""
    n = x.size
    for i in range(n):
        s = 0.0
        for j in range(max(0, i - b), min(n, i + b + 1)):
            s += A[i, b + j - i] * x[j]
        out[i] = s


@numba.njit(cache=True)
def _cho_solve_banded(cb, b, rhs, out):
    """Solve UᵀU x = rhs with U in LAPACK upper band storage (scipy.linalg.cholesky_banded)."""
    n = rhs.size
    for j in range(n):
        s = rhs[j]
        for i in range(max(0, j - b), j):
            s -= cb[b + i - j, j] * out[i]
        out[j] = s / cb[b, j]
    for i in range(n - 1, -1, -1):
        s = out[i]
        for j in range(i + 1, min(n, i + b + 1)):
            s -= cb[b + i - j, j] * out[j]
        out[i] = s / cb[b, i]


@numba.njit(cache=True)
def _solve_s(cb, b, Z, W, rhs, tmp, out):
    """S⁻¹ rhs with S = S₀ + U hG Uᵀ: out = y₀ − Z (W y₀), y₀ = S₀⁻¹ rhs (Woodbury)."""
    _cho_solve_banded(cb, b, rhs, out)
    r = Z.shape[1]
    for k in range(r):
        s = 0.0
        for i in range(out.size):
            s += W[k, i] * out[i]
        tmp[k] = s
    for i in range(out.size):
        s = 0.0
        for k in range(r):
            s += Z[i, k] * tmp[k]
        out[i] -= s


@numba.njit(cache=True)
def _midpoint_run(x, t0, h, k0, n_steps, stride, out, floor_index, i3, Mb, Kb, b, cb, Z, W, w,
                  p, u, load_kind, load_floor, amps, omegas, phases, pulse):
    """Advance steps k0 … n_steps − 1 of the implicit midpoint rule (structural DOFs in banded
    order; stepping and output as :func:`_rk4_run`).

    Returns (k, status): (n_steps, 0) when done; otherwise x is the starting state of the failed
    step k and status is 1 (Newton did not converge) or 2 (non-finite result).
    """
    n = Mb.shape[0]
    nd = n + 1
    m4, l4, g, r4, J = p[0], p[1], p[2], p[3], p[4]
    ml = m4 * l4
    rhs = np.empty(n)
    tmp = np.empty(n)
    y = np.empty(n)
    lr = np.empty(max(Z.shape[1], 1))
    w3 = w[i3]
    start = np.empty(x.size)
    for k in range(k0, n_steps):
        tm = t0 + (k + 0.5) * h
        for i in range(x.size):
            start[i] = x[i]
        q0 = start[:n]
        v0 = start[nd:nd + n]
        phi0, dphi0 = x[n], x[nd + n]
        _band_matvec(Mb, b, v0, rhs)
        _band_matvec(Kb, b, q0, tmp)
        for i in range(n):
            rhs[i] = 2.0 * rhs[i] - h * tmp[i]
        force = _force(tm, load_kind, amps, omegas, phases, pulse)
        for j in range(3):
            rhs[floor_index[j]] += h * u[j]
        rhs[floor_index[load_floor]] += h * force
        _solve_s(cb, b, Z, W, rhs, lr, y)
        y3 = y[i3]
        v03 = v0[i3]
        # scalar Newton for p = φ̇_m on the pendulum row
        pm = dphi0
        converged = False
        sigma = 0.0
        for _ in range(NEWTON_MAX_ITER):
            phim = phi0 + 0.5 * h * pm
            s, c = math.sin(phim), math.cos(phim)
            cm = ml * c
            dcm = -ml * s * 0.5 * h
            sigma = h * ml * s * pm * pm - 2.0 * cm * (pm - dphi0)
            dsigma = h * ml * (c * 0.5 * h * pm * pm + 2.0 * s * pm) - 2.0 * (dcm * (pm - dphi0)
                                                                              + cm)
            v3 = y3 + sigma * w3
            res = (2.0 * cm * (v3 - v03) + 2.0 * J * (pm - dphi0)
                   - h * (u[3] - m4 * g * l4 * s - r4 * pm))
            dres = (2.0 * dcm * (v3 - v03) + 2.0 * cm * w3 * dsigma + 2.0 * J
                    + h * (m4 * g * l4 * c * 0.5 * h + r4))
            delta = res / dres
            pm -= delta
            if not math.isfinite(pm):
                break
            if abs(delta) <= NEWTON_TOL * (1.0 + abs(pm)):
                converged = True
                break
        if not converged:
            return k, 1
        phim = phi0 + 0.5 * h * pm
        sigma = h * ml * math.sin(phim) * pm * pm - 2.0 * ml * math.cos(phim) * (pm - dphi0)
        finite = True
        for i in range(n):
            vm = y[i] + sigma * w[i]
            x[i] = q0[i] + h * vm
            x[nd + i] = 2.0 * vm - v0[i]
            if not (math.isfinite(x[i]) and math.isfinite(x[nd + i])):
                finite = False
        x[n] = phi0 + h * pm
        x[nd + n] = 2.0 * pm - dphi0
        if not (finite and math.isfinite(x[n]) and math.isfinite(x[nd + n])):
            for i in range(x.size):
                x[i] = start[i]
            return k, 2
        if (k + 1) % stride == 0:
            out[(k + 1) // stride, :] = x
    return n_steps, 0


# --- Python side ---------------------------------------------------------------------------------
def to_band(A: np.ndarray, b: int) -> np.ndarray:
    """A[i, j] for |i − j| ≤ b stored by diagonals, row i at columns b + j − i."""
    n = A.shape[0]
    band = np.zeros((n, 2 * b + 1))
    for d in range(-b, b + 1):
        i = np.arange(max(0, -d), min(n, n - d))
        band[i, b + d] = A[i, i + d]
    return band


def bandwidth(A: np.ndarray) -> int:
    """The largest |i − j| over the nonzero entries of ``A`` (0 for a zero matrix)."""
    i, j = np.nonzero(A)
    return int(np.max(np.abs(i - j))) if i.size else 0


def banded_order(model: FrameModel) -> np.ndarray:
    """A DOF order that makes M and K banded (reverse Cuthill–McKee on their pattern)."""
    s = model.structure
    pattern = csr_matrix((np.abs(s.mass) + np.abs(s.stiffness)) > 0)
    return np.asarray(reverse_cuthill_mckee(pattern, symmetric_mode=True), dtype=np.int64)


#: the kernels' failure codes as :func:`~stillframe.dynamics.integrators.floor_failure` causes
_CAUSE = {"rk4": {1: "error", 2: "non-finite"}, "midpoint": {1: "newton", 2: "non-finite"}}


class CompiledFrame:
    """A FrameModel prepared for the compiled kernels; :meth:`run` advances a state, subdividing
    failed steps as ``subdivision`` says (:mod:`stillframe.dynamics.integrators`), counted in
    ``subdivisions``."""

    def __init__(self, model: FrameModel, subdivision: Subdivision | None = None) -> None:
        self.model = model
        self.subdivision = Subdivision() if subdivision is None else subdivision
        self.subdivisions = 0
        s = model.structure
        p = model
        self.params = np.array([p.m4, p.l4, p.g, p.r4, p.pendulum_inertia])
        self.floor_index = np.asarray(p.floor_index, dtype=np.int64)
        self._banded: dict[float, tuple] = {}
        # midpoint: banded order of the structural DOFs
        self.order = banded_order(model)
        self.position = np.empty_like(self.order)
        self.position[self.order] = np.arange(self.order.size)
        parts = s.damping_parts
        if parts is None:  # a damping matrix given without its parts: treat it as low rank
            parts = _parts_of_matrix(s.damping)
        self.parts = parts

    # dense RK4 ----------------------------------------------------------------------------------
    def _rk4(self, x, t0, h, k0, n_steps, stride, out, u, load) -> tuple[int, int]:
        m = self.model
        return _rk4_run(x, t0, h, k0, n_steps, stride, out, self.subdivision.limit_code,
                        self.floor_index, m.i3, m.k_struct, m.c_struct, m.m_const_inv,
                        m.floor3_column, self.params, u, *load)

    # banded midpoint ----------------------------------------------------------------------------
    def banded_step_matrix(self, h: float) -> tuple:
        """(b, Cholesky band of S₀, Z, W, w) for step h, in banded DOF order (cached per h)."""
        if h in self._banded:
            return self._banded[h]
        s, o = self.model.structure, self.order
        parts = self.parts
        M = s.mass[np.ix_(o, o)]
        K = s.stiffness[np.ix_(o, o)]
        Mc = self.model.m_const[np.ix_(o, o)]
        b = max(bandwidth(Mc), bandwidth(K))
        S0 = 2.0 * Mc + h * (parts.mass_coefficient * M + parts.stiffness_coefficient * K) \
            + 0.5 * h * h * K
        upper = np.zeros((b + 1, S0.shape[0]))
        for d in range(b + 1):
            upper[b - d, d:] = np.diagonal(S0, d)
        try:
            cb = sla.cholesky_banded(upper, lower=False)
        except sla.LinAlgError:
            raise IntegrationError(
                f"integrator.dt: the implicit step matrix of {s.name} at dt = {h:g} s is not "
                "positive definite (damping too negative for this step); reduce integrator.dt"
            ) from None
        U = parts.shapes[o]
        Z = np.empty_like(U)
        for k in range(U.shape[1]):
            _cho_solve_banded(cb, b, U[:, k].copy(), Z[:, k])
        r = U.shape[1]
        hg = h * parts.gains
        W = np.linalg.solve(np.eye(r) + hg[:, None] * (U.T @ Z), hg[:, None] * U.T) if r else \
            np.zeros((0, U.shape[0]))
        e3 = np.zeros(U.shape[0])
        e3[self.position[self.model.i3]] = 1.0
        w = np.empty_like(e3)
        _solve_s(cb, b, Z, W, e3, np.empty(max(r, 1)), w)
        banded = (b, cb, Z, W, w, to_band(Mc, b), to_band(K, b))
        self._banded[h] = banded
        return banded

    def _to_banded_state(self, x: np.ndarray) -> np.ndarray:
        n = self.model.n_struct
        nd = n + 1
        y = x.copy()
        y[:n] = x[:n][self.order]
        y[nd:nd + n] = x[nd:nd + n][self.order]
        return y

    def _from_banded_states(self, states: np.ndarray) -> np.ndarray:
        n = self.model.n_struct
        nd = n + 1
        out = states.copy()
        out[:, :n] = states[:, :n][:, self.position]
        out[:, nd:nd + n] = states[:, nd:nd + n][:, self.position]
        return out

    def _midpoint(self, x, t0, h, k0, n_steps, stride, out, u, load) -> tuple[int, int]:
        b, cb, Z, W, w, Mb, Kb = self.banded_step_matrix(h)
        floor = self.position[self.floor_index]
        i3 = int(self.position[self.model.i3])
        return _midpoint_run(x, t0, h, k0, n_steps, stride, out, floor, i3, Mb, Kb, b, cb, Z, W,
                             w, self.params, u, *load)

    def _subdivide(self, kernel, method: str, x: np.ndarray, t: float, h: float, u, load,
                   depth: int, cause: str) -> None:
        """Advance x (in place) over [t, t + h) as two half steps, each halved again while it
        fails, down to the floor of ``subdivision.max_halvings``."""
        if depth > self.subdivision.max_halvings:
            raise floor_failure(cause, t, h, method, depth - 1)
        self.subdivisions += 1
        half = 0.5 * h
        scratch = np.empty((2, x.size))
        for start in (t, t + half):
            _, status = kernel(x, start, half, 0, 1, 1, scratch, u, load)
            if status:
                self._subdivide(kernel, method, x, start, half, u, load, depth + 1,
                                _CAUSE[method][status])

    def run(self, method: str, x0: np.ndarray, h: float, n_steps: int, *,
            load: FloorLoad | None = None, control: np.ndarray | None = None, t0: float = 0.0,
            stride: int = 1) -> np.ndarray:
        """States every ``stride`` steps (rows, the first is x0) after ``n_steps`` steps.

        A step that fails (Newton, a non-finite result, RK4's error estimate) is subdivided
        (class docstring); IntegrationError (like
        :func:`stillframe.dynamics.integrators.integrate`) for a non-finite x0 or a step still
        failing at the floor.
        """
        arrays = load_arrays(load)
        if arrays is None:
            raise ValueError("this load has no compiled form; use stillframe.dynamics.integrators")
        if not np.all(np.isfinite(x0)):
            raise floor_failure("non-finite", t0, h, method, 0)
        u = np.zeros(4) if control is None else np.asarray(control, float)
        out = np.empty((n_steps // stride + 1, x0.size))
        banded = method == "midpoint"
        x = self._to_banded_state(np.asarray(x0, float)) if banded else np.array(x0, float)
        out[0] = x
        kernel = self._midpoint if banded else self._rk4
        k = 0
        while True:
            k, status = kernel(x, t0, h, k, n_steps, stride, out, u, arrays)
            if not status:
                break
            self._subdivide(kernel, method, x, t0 + k * h, h, u, arrays, 1,
                            _CAUSE[method][status])
            k += 1
            if k % stride == 0:
                out[k // stride] = x
        return self._from_banded_states(out) if banded else out


def _parts_of_matrix(C: np.ndarray) -> DampingParts:
    """A damping matrix without known parts, as a (full-rank) low-rank term U diag(g) Uᵀ."""
    g, U = np.linalg.eigh(0.5 * (C + C.T))
    keep = np.abs(g) > 1e-14 * max(np.max(np.abs(g)), 1e-300)
    return DampingParts(0.0, 0.0, U[:, keep], g[keep])


Observer = Callable[[int, float, np.ndarray], None]


def compiled_integrate(model: FrameModel, load: FloorLoad | None, method: str, x0: np.ndarray,
                       dt: float, n_steps: int, *, observer: Observer | None = None,
                       chunk: int = 4096, subdivision: Subdivision | None = None) -> int:
    """Like :func:`stillframe.dynamics.integrators.integrate` on the compiled kernels, in chunks;
    returns the number of subdivisions."""
    frame = CompiledFrame(model, subdivision)
    x = np.array(x0, float)
    if observer:
        observer(0, 0.0, x)
    done = 0
    while done < n_steps:
        steps = min(chunk, n_steps - done)
        states = frame.run(method, x, dt, steps, load=load, t0=done * dt)
        if observer:
            for j in range(1, steps + 1):
                observer(done + j, (done + j) * dt, states[j])
        x = states[-1]
        done += steps
    return frame.subdivisions


def compiles(load: object, method: str) -> bool:
    """Whether :func:`compiled_integrate` handles this load and method."""
    return method in COMPILED_METHODS and load_arrays(load) is not None
