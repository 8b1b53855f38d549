"""The frame pHDAE's AVF midpoint step, compiled (numba), with the linear part factorised once.

The frame of :mod:`stillframe.dynamics.ph.frame` has a special shape that makes the step of
:class:`~stillframe.dynamics.ph.integrator.MidpointDAE` cheap without changing it:

- every connection except the pendulum's revolute joint is linear and constant (the columns'
  frame angles are held by their clamps, so ω = 0 for every column and floor; no structural
  block carries gravity). The structural velocities therefore live in the constant null space
  ν_s = P ξ of those constraints (the reduction of eq. 47), and the structural rows of the
  AVF step are linear with constant matrices: M̂ = PᵀMP, D̂ = DP, R̂ = PᵀRP, B̂ = PᵀB;
- the revolute joint's constraint g = p_floor3 − p_pendulum is linear in q, so its multiplier
  enters the structure only as the horizontal force λ_x on floor 3 (the vertical one is taken by
  the floor's slide).

One step, for the midpoint velocities ξ̄ and stresses σ̄ = σ₀ + (h/2)C⁻¹D̂ξ̄:

    S ξ̄ = 2M̂ξ₀ − hD̂ᵀσ₀ + hB̂ū + h b̂ λ_x,     S = 2M̂ + hR̂ + (h²/2) D̂ᵀC⁻¹D̂,

so ξ̄ = a + λ_x w with S factorised once per step size. The pendulum's three momentum rows with
the joint (R(θ̄) v̄' = [v̄_floor3, 0]) leave one scalar equation in ω̄ (λ_x and the floor
velocity eliminated in closed form), solved by Newton with its exact derivative. Gravity's AVF
average uses the same 4-point Gauss–Legendre rule as :class:`MidpointDAE`, so both give the
same step to the Newton tolerance (tested), and the discrete power balance

    H(e₁) − H(e₀) = h(ȳᵀū − ν̄ᵀRν̄)

holds to round-off. Each step also returns its port energies (h ȳᵢūᵢ per port group) and the
dissipated energy, so the balance can be published (:mod:`stillframe.plant.ph_energy`).

The kernel runs in the structure's modal coordinates (:class:`CompiledFramePH`); the pendulum's
hinge follows floor 3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import scipy.linalg as sla

from stillframe.dynamics.ph.integrator import AVF_POINTS
from stillframe.dynamics.ph.joints import Link
from stillframe.dynamics.ph.system import PHSystem, RotaryDamper
from stillframe.errors import InputError, IntegrationError

PENDULUM = "pendulum"
FLOORS = ("floor1", "floor2", "floor3")
NEWTON_TOL = 1e-14
NEWTON_MAX_ITER = 50
#: energies per step kept by the kernel: excitation, actuator, noise ports, dissipated
ENERGY_TERMS = ("excitation", "actuator", "noise", "dissipated")

_S, _W = np.polynomial.legendre.leggauss(AVF_POINTS)
_S, _W = 0.5 * (_S + 1.0), 0.5 * _W


@dataclass(frozen=True)
class FrameReduction:
    """The constant null-space reduction of the frame's structural constraints."""

    P: np.ndarray            # ν_s = P ξ (orthonormal columns)
    structural: np.ndarray   # indices of the structural ν (and q) in the full system
    mass: np.ndarray         # M̂
    stiffness: np.ndarray    # K̂ = D̂ᵀC⁻¹D̂
    coupling: np.ndarray     # D̂ (stresses × ξ)
    position_map: np.ndarray  # A P: q_s − q_rest = A P η
    floor_rows: np.ndarray   # 3 × n_ξ: floor i's horizontal velocity = floor_rows[i] ξ

    @property
    def n(self) -> int:
        return self.P.shape[1]


def frame_reduction(system: PHSystem, q_rest: np.ndarray) -> FrameReduction:
    """P, M̂, K̂, D̂ of the frame's structure about ``q_rest`` (valid everywhere: the structural
    constraints are constant, see the module docstring)."""
    if PENDULUM not in system.bodies:
        raise InputError("the compiled frame step needs the frame pHDAE (a 'pendulum' body)")
    pend = system.q_slices[PENDULUM]
    structural = np.array([i for i in range(system.n_q) if not pend.start <= i < pend.stop])
    rows, start = [], 0
    for c in system.connections:
        k = len(c.components)
        bodies = {c.a[0], c.b[0]} if isinstance(c, Link) else {c.port[0]}
        if PENDULUM not in bodies:
            rows.extend(range(start, start + k))
        start += k
    _, Dg, _ = system.constraints(q_rest, 0.0)
    A = system.kinematics(q_rest)
    C = (Dg @ A)[np.ix_(rows, structural)]
    P = sla.null_space(C)
    mass = P.T @ system.mass[np.ix_(structural, structural)] @ P
    D = system.stress_coupling[:, structural] @ P
    stiffness = D.T @ np.linalg.solve(system.compliance, D)
    floor_rows = np.array([P[np.searchsorted(structural, system.q_slices[f].start)]
                           for f in FLOORS])
    position_map = A[np.ix_(structural, structural)] @ P
    return FrameReduction(P, structural, 0.5 * (mass + mass.T), 0.5 * (stiffness + stiffness.T),
                          D, position_map, floor_rows)


@numba.njit(cache=True)
def _avg_cos(theta0: float, dtheta: float, nodes: np.ndarray, weights: np.ndarray,
             ) -> tuple[float, float]:
    """∫₀¹ cos(θ₀ + sΔθ) ds by Gauss–Legendre, and its derivative in Δθ."""
    a, da = 0.0, 0.0
    for i in range(nodes.size):
        arg = theta0 + nodes[i] * dtheta
        a += weights[i] * math.cos(arg)
        da -= weights[i] * nodes[i] * math.sin(arg)
    return a, da


@numba.njit(cache=True)
def _frame_run(z, n_steps, h, loads, control, noise, Phi_x, Phi_q, Gam, wv,
               Rhat, floor_rows, pend, nodes, weights, record, energy, states):
    """Advance ``n_steps`` AVF midpoint steps of the reduced frame state ``z`` in place.

    ``loads[k]``: floor forces at step k's midpoint; ``control`` and ``noise``: [f1, f2, f3,
    torque] held over the call. ``record[k]``: floor displacements and velocities after step
    k; ``energy[k]``: step k's energies of :data:`ENERGY_TERMS`; ``states[k]`` the state after
    step k if ``states`` has rows. Returns n_steps, or −(k + 1) if
    Newton failed at step k, or k + 1 if the state became non-finite at step k.
    """
    n = Phi_x.shape[0]
    it = 2 * n
    m, S, IP, g, r4 = pend[0], pend[1], pend[2], pend[3], pend[4]
    a = np.empty(n)
    xb = np.empty(n)
    u = np.empty(3)
    two_h = 2.0 / h
    for k in range(n_steps):
        for j in range(3):
            u[j] = loads[k, j] + control[j] + noise[j]
        tau = control[3] + noise[3]
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += Phi_x[i, j] * z[n + j]
            for j in range(n):
                s += Phi_q[i, j] * z[j]
            for j in range(3):
                s += Gam[i, j] * u[j]
            a[i] = s
        ca, cw = 0.0, 0.0
        for i in range(n):
            ca += floor_rows[2, i] * a[i]
            cw += floor_rows[2, i] * wv[i]
        th0, v0x, v0y, w0 = z[it], z[it + 1], z[it + 2], z[it + 3]
        p = w0
        converged = False
        for _ in range(NEWTON_MAX_ITER):
            thm = th0 + 0.5 * h * p
            c, s = math.cos(thm), math.sin(thm)
            dc, ds = -0.5 * h * s, 0.5 * h * c
            avg, davg = _avg_cos(th0, h * p, nodes, weights)
            davg *= h
            alpha = two_h * (m * (c * v0x - s * v0y) + S * s * (p - w0)) + S * c * p * p
            dalpha = (two_h * (m * (dc * v0x - ds * v0y) + S * (ds * (p - w0) + s))
                      + S * (dc * p * p + 2.0 * c * p))
            den = 1.0 + cw * two_h * m
            V = (ca + cw * alpha) / den
            dV = cw * dalpha / den
            res = (two_h * (S * (-s * V - v0y) + IP * (p - w0)) + g * S * avg + S * p * c * V
                   + r4 * p - tau)
            dres = (two_h * (S * (-ds * V - s * dV) + IP) + g * S * davg
                    + S * (c * V + p * dc * V + p * c * dV) + r4)
            delta = res / dres
            p -= delta
            if not math.isfinite(p):
                break
            if abs(delta) <= NEWTON_TOL * (1.0 + abs(p)):
                converged = True
                break
        if not converged:
            return -(k + 1)
        thm = th0 + 0.5 * h * p
        c, s = math.cos(thm), math.sin(thm)
        alpha = two_h * (m * (c * v0x - s * v0y) + S * s * (p - w0)) + S * c * p * p
        V = (ca + cw * alpha) / (1.0 + cw * two_h * m)
        lam = alpha - two_h * m * V
        diss = r4 * p * p
        finite = True
        for i in range(n):
            xb[i] = a[i] + lam * wv[i]
        for i in range(n):
            rx = 0.0
            for j in range(n):
                rx += Rhat[i, j] * xb[j]
            diss += xb[i] * rx
        for i in range(n):
            z[i] += h * xb[i]
            z[n + i] = 2.0 * xb[i] - z[n + i]
            if not math.isfinite(z[n + i]):
                finite = False
        z[it] = th0 + h * p
        z[it + 1] = 2.0 * c * V - v0x
        z[it + 2] = -2.0 * s * V - v0y
        z[it + 3] = 2.0 * p - w0
        p_exc, p_act, p_noise = 0.0, control[3] * p, noise[3] * p
        for f in range(3):
            x, v = 0.0, 0.0
            for i in range(n):
                x += floor_rows[f, i] * z[i]
                v += floor_rows[f, i] * xb[i]
            p_exc += loads[k, f] * v
            p_act += control[f] * v
            p_noise += noise[f] * v
            record[k, f] = x
        for f in range(3):
            v = 0.0
            for i in range(n):
                v += floor_rows[f, i] * z[n + i]
            record[k, 3 + f] = v
        energy[k, 0] = h * p_exc
        energy[k, 1] = h * p_act
        energy[k, 2] = h * p_noise
        energy[k, 3] = h * diss
        if states.shape[0] > 0:
            states[k, :] = z
        if not finite or not math.isfinite(z[it + 3]):
            return k + 1
    return n_steps


class CompiledFramePH:
    """The frame pHDAE stepped by :func:`_frame_run`: built once per step size, then
    :meth:`run` advances chunks of steps of the reduced state.

    Coordinates: the structure's modes ξ = Φζ of (K̂, M̂) (Φᵀ M̂ Φ = I, Φᵀ K̂ Φ = Ω²) and their
    positions η, with the stresses condensed: σ = C⁻¹D̂Φη (Cσ̇ = D̂ξ keeps σ − C⁻¹D̂Φη constant,
    zero from the consistent initial state), so ½σᵀCσ = ½ηᵀΩ²η. The AVF midpoint rule commutes
    with these linear changes of coordinates, so the step is still that of :class:`MidpointDAE`
    (tested to 1e-10), and S = 2I + hR̃ + (h²/2)Ω² is diagonal for Rayleigh and modal damping:
    its inverse is exact per mode, which keeps the balance at round-off of H (in the σ, ξ
    coordinates the stiff axial modes, cond S ~ 1e6, cost five digits of it).

    Reduced state ``z = [η, ζ, θ, v'_x, v'_y, ω]`` (pendulum frame angle, body-frame velocities).
    """

    name = "midpoint (AVF, pHDAE, compiled)"

    def __init__(self, system: PHSystem, q_rest: np.ndarray, h: float,
                 structural_damping: np.ndarray | None = None) -> None:
        if h <= 0:
            raise InputError(f"integrator.dt: the time step must be > 0, got {h}")
        self.system, self.h = system, h
        self.q_rest = np.asarray(q_rest, float)
        red = frame_reduction(system, self.q_rest)
        w2, phi = sla.eigh(red.stiffness, red.mass)
        damping = np.zeros((red.n, red.n)) if structural_damping is None else structural_damping
        self.reduction = FrameReduction(
            red.P @ phi, red.structural, np.eye(red.n), np.diag(w2), red.coupling @ phi,
            red.position_map @ phi, red.floor_rows @ phi)
        red = self.reduction
        self.omega2 = w2
        self.R = phi.T @ damping @ phi
        S = 2.0 * np.eye(red.n) + h * self.R + np.diag(0.5 * h * h * w2)
        try:
            factor = sla.cho_factor(S)
        except sla.LinAlgError:
            raise IntegrationError(
                f"integrator.dt: the implicit step matrix of the pH frame at dt = {h:g} s is not "
                "positive definite (damping too negative for this step); reduce integrator.dt"
            ) from None
        solve = lambda rhs: sla.cho_solve(factor, rhs)  # noqa: E731
        self.Phi_x = solve(2.0 * np.eye(red.n))
        self.Phi_q = solve(-h * np.diag(w2))
        self.Gam = solve(h * red.floor_rows.T)
        self.wv = solve(h * red.floor_rows[2])
        self.stress_map = np.linalg.solve(system.compliance, red.coupling)
        pend = system.bodies[PENDULUM]
        self.pend = np.array([pend.mass, pend.static_moment, pend.inertia, pend.gravity,
                              self._hinge_damping()])
        self.size = 2 * red.n + 4

    def _hinge_damping(self) -> float:
        return float(sum(d.coefficient for d in self.system.dampers
                         if isinstance(d, RotaryDamper)))

    # state maps ---------------------------------------------------------------------------
    def reduce(self, e: np.ndarray) -> np.ndarray:
        """The reduced state z of a full pHDAE state e (consistent: connections met, stresses
        those of the deformation)."""
        sys, red = self.system, self.reduction
        q, nu, s = sys.split(np.asarray(e, float))
        idx = red.structural
        eta = np.linalg.lstsq(red.position_map, q[idx] - self.q_rest[idx], rcond=None)[0]
        xi = np.linalg.lstsq(red.P, nu[idx], rcond=None)[0]
        mismatch = np.max(np.abs(s - self.stress_map @ eta), initial=0.0)
        if mismatch > 1e-6 * max(1.0, np.max(np.abs(s), initial=0.0)):
            raise InputError("the pH state's stresses are not those of its deformation "
                             f"(off by {mismatch:.3g}); start from a consistent state")
        pend = sys.q_slices[PENDULUM]
        return np.concatenate([eta, xi, [q[pend][2]], nu[pend]])

    def expand(self, z: np.ndarray) -> np.ndarray:
        """The full pHDAE state e of a reduced state z."""
        sys, red = self.system, self.reduction
        n = red.n
        q = self.q_rest.copy()
        nu = np.zeros(sys.n_q)
        idx = red.structural
        q[idx] += red.position_map @ z[:n]
        nu[idx] = red.P @ z[n:2 * n]
        pend = sys.q_slices[PENDULUM]
        floor3 = sys.q_slices["floor3"].start
        q[pend.start:pend.start + 3] = [q[floor3], q[floor3 + 1], z[2 * n]]
        nu[pend] = z[-3:]
        return sys.state(q, nu, self.stress_map @ z[:n])

    def _pendulum_mass(self) -> np.ndarray:
        m, S, IP = self.pend[:3]
        return np.array([[m, 0.0, 0.0], [0.0, m, S], [0.0, S, IP]])

    def energies(self, states: np.ndarray) -> np.ndarray:
        """H above rest of reduced states (rows): ½|ζ|² + ½ηᵀΩ²η + ½ν_pᵀM_pν_p + g s (1 − cos φ),
        φ = θ + π/2 (the last as 2 g s sin²(φ/2): no cancellation near rest)."""
        n = self.reduction.n
        z = np.atleast_2d(states)
        eta, zeta, theta, nu_p = z[:, :n], z[:, n:2 * n], z[:, 2 * n], z[:, -3:]
        g, S = self.pend[3], self.pend[1]
        return (0.5 * np.sum(zeta**2, axis=1) + 0.5 * (eta**2) @ self.omega2
                + 0.5 * np.einsum("ki,ij,kj->k", nu_p, self._pendulum_mass(), nu_p)
                + 2.0 * g * S * np.sin(0.5 * (theta + 0.5 * np.pi)) ** 2)

    def energy_changes(self, states: np.ndarray) -> np.ndarray:
        """H(z_{k+1}) − H(z_k) between successive rows, in difference form (½Δxᵀ A (x₁ + x₀)
        and g s · 2 cos θ̄ sin(Δθ/2): no cancellation), for the balance residual."""
        n = self.reduction.n
        z = np.atleast_2d(states)
        d, m_ = np.diff(z, axis=0), z[1:] + z[:-1]
        g, S = self.pend[3], self.pend[1]
        return (0.5 * np.sum(d[:, n:2 * n] * m_[:, n:2 * n], axis=1)
                + 0.5 * (d[:, :n] * m_[:, :n]) @ self.omega2
                + 0.5 * np.einsum("ki,ij,kj->k", d[:, -3:], self._pendulum_mass(), m_[:, -3:])
                + g * S * 2.0 * np.cos(0.5 * m_[:, 2 * n]) * np.sin(0.5 * d[:, 2 * n]))

    def floor_accelerations(self, z: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The floors' horizontal accelerations of the index-1 form at state z under the port
        efforts u = [f1, f2, f3, torque] (ζ̇, ν̇_p and the joint force from one linear solve)."""
        red, n = self.reduction, self.reduction.n
        eta, zeta, theta, nu = z[:n], z[n:2 * n], z[2 * n], z[-3:]
        m, S, _, g, r4 = self.pend
        c, s = np.cos(theta), np.sin(theta)
        rot = np.array([[c, -s], [s, c]])
        b = red.floor_rows[2]
        pi0, pi1 = m * nu[0], m * nu[1] + S * nu[2]
        f_p = np.array([-s * g * m + pi1 * nu[2], -c * g * m - pi0 * nu[2],
                        -g * S * c - pi1 * nu[0] + pi0 * nu[1] - r4 * nu[2] + u[3]])
        K = np.zeros((n + 5, n + 5))
        K[:n, :n] = np.eye(n)
        K[:n, n + 3] = -b
        K[n:n + 3, n:n + 3] = self._pendulum_mass()
        K[n:n + 2, n + 3:] = rot.T
        K[n + 3:, n:n + 2] = rot
        K[n + 3, :n] = -b
        rhs = np.concatenate([-self.omega2 * eta - self.R @ zeta + red.floor_rows.T @ u[:3],
                              f_p, -nu[2] * rot @ np.array([-nu[1], nu[0]])])
        return red.floor_rows @ np.linalg.solve(K, rhs)[:n]

    def energy(self, z: np.ndarray) -> float:
        return float(self.energies(z)[0])

    def readings(self, states: np.ndarray) -> dict[str, np.ndarray]:
        """Floor displacements and velocities (rows × 3), φ and φ̇ of reduced states."""
        red, n = self.reduction, self.reduction.n
        z = np.atleast_2d(states)
        return {"floors": z[:, :n] @ red.floor_rows.T,
                "floor_velocities": z[:, n:2 * n] @ red.floor_rows.T,
                "phi": z[:, 2 * n] + 0.5 * np.pi, "phi_rate": z[:, -1]}

    def run(self, z: np.ndarray, loads: np.ndarray, control: np.ndarray, noise: np.ndarray,
            t0: float = 0.0, states: np.ndarray | None = None,
            ) -> tuple[np.ndarray, np.ndarray]:
        """Advance ``z`` in place by len(loads) steps (``loads[k]``: floor forces at step k's
        midpoint; ``control``, ``noise``: [f1, f2, f3, torque] held); returns the floor
        displacements and velocities after each step and each step's energies of
        :data:`ENERGY_TERMS` (rows); ``states`` (rows × z.size), if given, gets the states."""
        steps = loads.shape[0]
        record = np.empty((steps, 6))
        energy = np.empty((steps, len(ENERGY_TERMS)))
        out = np.empty((0, z.size)) if states is None else states
        done = _frame_run(z, steps, self.h, np.ascontiguousarray(loads, float),
                          np.asarray(control, float), np.asarray(noise, float), self.Phi_x,
                          self.Phi_q, self.Gam, self.wv, self.R,
                          self.reduction.floor_rows, self.pend, _S, _W, record, energy, out)
        if done < 0:
            raise IntegrationError(f"integrator.dt: pH step: Newton did not converge at "
                                   f"t = {t0 + (-done - 1) * self.h:.6g} s; reduce the time step")
        if done != steps:
            raise IntegrationError(f"integrator.dt: the pH state became non-finite at "
                                   f"t ≈ {t0 + done * self.h:.6g} s; reduce integrator.dt or "
                                   "limit the actuators")
        return record, energy
