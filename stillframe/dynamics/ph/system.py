"""Assembly of blocks and connections into one pHDAE (seed 000 §5, eq. 38–42).

    E ė = (J(e) − R(e)) z(e) + G(e) λ + B(e) u,     0 = G(e)ᵀ z + ∂g/∂t,
    y = B(e)ᵀ z,                                   ∂H/∂e = Eᵀ z,

with e = [q, ν, σ] of all bodies stacked by kind, H = ½νᵀMν + ½σᵀCσ + V(q), and the power
balance dH/dt = yᵀu − zᵀRz − λᵀ ∂g/∂t (the last term is the power of prescribed motions).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from stillframe.dynamics.ph.body import FloatingBody
from stillframe.dynamics.ph.joints import Connection, Port
from stillframe.errors import InputError

__all__ = ["BodyDamping", "Damper", "DistributedInput", "Input", "PHSystem", "PortInput",
           "RotaryDamper", "VelocityDamping"]


@dataclass(frozen=True)
class PortInput:
    """An effort input at a port: force/torque along ``direction`` = [F_x, F_y, T] (inertial);
    its output is the port's velocity along the same direction."""

    name: str
    port: Port
    direction: tuple[float, float, float]


@dataclass(frozen=True)
class DistributedInput:
    """A distributed port of one body (B_d of eq. 15): a constant column in that body's ν."""

    name: str
    body: str
    column: np.ndarray


@dataclass(frozen=True)
class RotaryDamper:
    """R = r c cᵀ on the relative angular velocity of two ports (a lossy revolute joint)."""

    a: Port
    b: Port
    coefficient: float


@dataclass(frozen=True)
class BodyDamping:
    """A constant R ⪰ 0 on one body's velocities ν."""

    body: str
    matrix: np.ndarray


@dataclass(frozen=True)
class VelocityDamping:
    """A constant R ⪰ 0 on the velocities ν[indices] of several bodies (a structure's damping
    written in the null space of its constraints, :mod:`stillframe.dynamics.ph.scene_model`)."""

    indices: np.ndarray
    matrix: np.ndarray


Input = PortInput | DistributedInput
Damper = RotaryDamper | BodyDamping | VelocityDamping


class PHSystem:
    """Blocks and their connections, like the paper's block diagrams (Fig. 3–7)."""

    def __init__(self, bodies: Sequence[FloatingBody], connections: Sequence[Connection],
                 inputs: Sequence[Input] = (), dampers: Sequence[Damper] = (),
                 name: str = "ph") -> None:
        self.name = name
        names = [b.name for b in bodies]
        if len(set(names)) != len(names):
            raise InputError(f"body names must be unique, got {names}")
        self.bodies = {b.name: b for b in bodies}
        self.connections = list(connections)
        self.inputs = list(inputs)
        self.dampers = list(dampers)
        self.q_slices: dict[str, slice] = {}
        self.s_slices: dict[str, slice] = {}
        nq = ns = 0
        for b in bodies:
            self.q_slices[b.name] = slice(nq, nq + b.n_q)
            self.s_slices[b.name] = slice(ns, ns + b.n_stress)
            nq, ns = nq + b.n_q, ns + b.n_stress
        self.n_q, self.n_stress = nq, ns
        self.n = 2 * nq + ns
        self.n_constraints = sum(len(c.components) for c in self.connections)
        self._mass = sla.block_diag(*(b.mass_matrix() for b in bodies))
        self._compliance = sla.block_diag(*(b.compliance() for b in bodies)) if ns else \
            np.zeros((0, 0))
        self._coupling = np.zeros((ns, nq))
        for b in bodies:
            self._coupling[self.s_slices[b.name], self.q_slices[b.name]] = b.stress_coupling()
        self._E = sla.block_diag(np.eye(nq), self._mass, self._compliance)

    # state layout ----------------------------------------------------------------------------
    def split(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q, ν, σ)`` of the state e: positions, velocities and stresses of all bodies, stacked
        by kind."""
        nq = self.n_q
        return e[:nq], e[nq:2 * nq], e[2 * nq:]

    def body_state(self, e: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q, ν, σ)`` of body ``name`` within the state e."""
        q, nu, s = self.split(e)
        sl = self.q_slices[name]
        return q[sl], nu[sl], s[self.s_slices[name]]

    def port_position(self, q: np.ndarray, port: Port) -> tuple[np.ndarray, np.ndarray]:
        """Port position [x, y, φ] and its Jacobian over all q."""
        body, name = port
        if body not in self.bodies:
            raise InputError(f"no body {body!r} (have {sorted(self.bodies)})")
        sl = self.q_slices[body]
        p, local = self.bodies[body].port(q[sl], name)
        jac = np.zeros((3, self.n_q))
        jac[:, sl] = local
        return p, jac

    # operators -------------------------------------------------------------------------------
    @property
    def descriptor(self) -> np.ndarray:
        """E = blockdiag(I, M, C), the descriptor matrix of seed 000 eq. 38–42."""
        return self._E

    @property
    def mass(self) -> np.ndarray:
        """M: the bodies' mass matrices, block diagonal."""
        return self._mass

    @property
    def compliance(self) -> np.ndarray:
        """C: the bodies' compliance matrices of the stresses, block diagonal (0 × 0 without
        stresses)."""
        return self._compliance

    @property
    def stress_coupling(self) -> np.ndarray:
        """D: the coupling of the stresses to the velocities (n_stress × n_q) in the
        interconnection."""
        return self._coupling

    def kinematics(self, q: np.ndarray) -> np.ndarray:
        """A(q): the bodies' kinematic matrices q̇ = A(q) ν, block diagonal."""
        A = np.zeros((self.n_q, self.n_q))
        for name, b in self.bodies.items():
            sl = self.q_slices[name]
            A[sl, sl] = b.kinematics(q[sl])
        return A

    def interconnection(self, e: np.ndarray) -> np.ndarray:
        """[[0, A, 0], [−Aᵀ, J_g, −Dᵀ], [0, D, 0]]: skew for every state."""
        q, nu, _ = self.split(e)
        nq = self.n_q
        A = self.kinematics(q)
        Jg = np.zeros((nq, nq))
        for name, b in self.bodies.items():
            sl = self.q_slices[name]
            Jg[sl, sl] = b.gyroscopic(q[sl], nu[sl])
        D = self._coupling
        out = np.zeros((self.n, self.n))
        out[:nq, nq:2 * nq] = A
        out[nq:2 * nq, :nq] = -A.T
        out[nq:2 * nq, nq:2 * nq] = Jg
        out[nq:2 * nq, 2 * nq:] = -D.T
        out[2 * nq:, nq:2 * nq] = D
        return out

    def potential_gradient(self, q: np.ndarray) -> np.ndarray:
        """∂V/∂q of all bodies, stacked."""
        return np.concatenate([b.potential_gradient(q[self.q_slices[n]])
                               for n, b in self.bodies.items()])

    def z(self, e: np.ndarray) -> np.ndarray:
        """Efforts [∂_q V, ν, σ] with ∂H/∂e = Eᵀ z (eq. 16, 31)."""
        q, nu, s = self.split(e)
        return np.concatenate([self.potential_gradient(q), nu, s])

    def hamiltonian(self, e: np.ndarray) -> float:
        """H = ½νᵀMν + ½σᵀCσ + V(q) at the state e [J]."""
        q, nu, s = self.split(e)
        V = sum(b.potential(q[self.q_slices[n]]) for n, b in self.bodies.items())
        return 0.5 * nu @ self._mass @ nu + 0.5 * s @ self._compliance @ s + V

    def dissipation(self, q: np.ndarray) -> np.ndarray:
        """R(q) ⪰ 0 on ν."""
        R = np.zeros((self.n_q, self.n_q))
        if not self.dampers:
            return R
        A = self.kinematics(q)
        for d in self.dampers:
            if isinstance(d, RotaryDamper):
                c = (self.port_position(q, d.a)[1][2] - self.port_position(q, d.b)[1][2]) @ A
                R += d.coefficient * np.outer(c, c)
            elif isinstance(d, VelocityDamping):
                R[np.ix_(d.indices, d.indices)] += d.matrix
            else:
                sl = self.q_slices[d.body]
                R[sl, sl] += d.matrix
        return R

    def input_matrix(self, q: np.ndarray) -> np.ndarray:
        """B_ν(q) (n_q × inputs): Aᵀ(∂p/∂q)ᵀ d for port inputs, B_d columns for distributed."""
        B = np.zeros((self.n_q, len(self.inputs)))
        if not self.inputs:
            return B
        A = self.kinematics(q)
        for k, inp in enumerate(self.inputs):
            if isinstance(inp, PortInput):
                B[:, k] = A.T @ self.port_position(q, inp.port)[1].T @ np.asarray(inp.direction)
            else:
                B[self.q_slices[inp.body], k] = inp.column
        return B

    def outputs(self, e: np.ndarray) -> np.ndarray:
        """y = Bᵀ z: the velocities conjugate to the inputs."""
        q, nu, _ = self.split(e)
        return self.input_matrix(q).T @ nu

    def constraints(self, q: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """g(q, t), ∂g/∂q and ∂g/∂t of all connections, stacked."""
        if not self.connections:
            return np.zeros(0), np.zeros((0, self.n_q)), np.zeros(0)
        parts = [c.residual(self.port_position, q, t) for c in self.connections]
        rates = [c.rate(t) for c in self.connections]
        return (np.concatenate([p[0] for p in parts]), np.vstack([p[1] for p in parts]),
                np.concatenate(rates))

    def constraint_matrix(self, q: np.ndarray, t: float) -> np.ndarray:
        """G = [0; (∂g/∂q A)ᵀ; 0] (n × constraints): the transformer interconnections."""
        G = np.zeros((self.n, self.n_constraints))
        G[self.n_q:2 * self.n_q] = (self.constraints(q, t)[1] @ self.kinematics(q)).T
        return G

    def power_terms(self, e: np.ndarray, u: np.ndarray, lam: np.ndarray, t: float,
                    ) -> tuple[float, float, float]:
        """(yᵀu, zᵀRz, λᵀ∂g/∂t) at one state: dH/dt = yᵀu − zᵀRz − λᵀ∂g/∂t."""
        q, nu, _ = self.split(e)
        supplied = float(self.outputs(e) @ u) if self.inputs else 0.0
        rate = self.constraints(q, t)[2]
        return supplied, float(nu @ self.dissipation(q) @ nu), float(lam @ rate)

    def state(self, q: np.ndarray, nu: np.ndarray | None = None,
              stress: np.ndarray | None = None) -> np.ndarray:
        """The state e = [q, ν, σ] from positions and, when given, velocities and stresses (zero
        otherwise)."""
        nu = np.zeros(self.n_q) if nu is None else nu
        stress = np.zeros(self.n_stress) if stress is None else stress
        return np.concatenate([q, nu, stress])

    def assemble(self, q_guess: np.ndarray, t: float = 0.0, tol: float = 1e-13) -> np.ndarray:
        """Gauss–Newton (minimum-norm steps) from ``q_guess`` onto g(q, t) = 0."""
        q = np.array(q_guess, dtype=float)
        for _ in range(50):
            g, Dg, _ = self.constraints(q, t)
            if g.size == 0 or np.max(np.abs(g)) < tol:
                return q
            q -= np.linalg.lstsq(Dg, g, rcond=None)[0]
        raise InputError("the connections cannot be assembled from the given positions")

    def consistent_velocity(self, q: np.ndarray, nu_guess: np.ndarray, t: float = 0.0,
                            ) -> np.ndarray:
        """The M-nearest ν to ``nu_guess`` with ∂g/∂q A ν + ∂g/∂t = 0."""
        _, Dg, rate = self.constraints(q, t)
        if rate.size == 0:
            return nu_guess
        C = Dg @ self.kinematics(q)
        M = self._mass
        k = C.shape[0]
        kkt = np.block([[M, C.T], [C, np.zeros((k, k))]])
        rhs = np.concatenate([M @ nu_guess, -rate])
        return np.linalg.solve(kkt, rhs)[:self.n_q]
