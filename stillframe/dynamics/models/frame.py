"""The rig's nonlinear equations of motion: a linear structure with a pendulum on floor 3.

M(q) q̈ = Q(q, q̇, u), thesis eq. 5.57 (lumped) and 5.154 (FE), written in the pendulum angle
φ = θ − 3π/2 measured from hanging (eq. 5.60), so sin θ = −cos φ and cos θ = sin φ:

    M(q) = blockdiag(M_s + m4 e3 e3ᵀ, J) + m4 L4 cos φ (e3 e_φᵀ + e_φ e3ᵀ),   J = m4 L4² + I_zz,4
    Q    = −K_s q_s − C_s q̇_s + m4 L4 sin φ φ̇² e3 − (m4 g L4 sin φ + r4 φ̇) e_φ + B u

with e3 the floor-3 DOF. Viscous terms as in eq. 5.237 (hinge damping σ4 = r4; structural
damping from :mod:`stillframe.dynamics.models.damping`). Inputs u = [f1, f2, f3, C]: horizontal
forces on floors 1–3 (excitation, floor-3 actuator) and the hinge torque (eq. 5.56).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from stillframe.config.scene import Rig
from stillframe.dynamics.models.structure import Structure

INPUT_NAMES = ("f1", "f2", "f3", "torque")


@dataclass(frozen=True)
class LinearModel:
    """M ẍ + C ẋ + K x = B u about the hanging equilibrium (thesis eq. 5.59–5.66, 5.156–5.163)."""

    mass: np.ndarray
    damping: np.ndarray
    stiffness: np.ndarray
    input_matrix: np.ndarray
    dof_names: tuple[str, ...]

    def state_space(self) -> tuple[np.ndarray, np.ndarray]:
        """First-order A, B for the state [x, ẋ]."""
        n = self.mass.shape[0]
        minv_k = sla.solve(self.mass, np.hstack([self.stiffness, self.damping, self.input_matrix]))
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-minv_k[:, :n], -minv_k[:, n:2 * n]]])
        B = np.vstack([np.zeros_like(self.input_matrix), minv_k[:, 2 * n:]])
        return A, B


class FrameModel:
    """Nonlinear structure + pendulum model; q = [q_s, φ] (the structure's DOFs, then φ)."""

    def __init__(self, structure: Structure, rig: Rig) -> None:
        if structure.damping is None:
            raise ValueError(
                "the structure needs its damping matrix (stillframe.dynamics.models.damping)")
        p = rig.pendulum
        self.structure = structure
        self.name = structure.name
        self.n_struct = structure.n_dof
        self.n_dof = self.n_struct + 1
        self.phi_index = self.n_struct
        self.floor_index = np.asarray(structure.floor_index)
        self.dof_names = (*structure.dof_names, "phi")
        self.m4, self.l4, self.r4, self.g = p.mass, p.half_length, p.hinge_damping, rig.gravity
        self.pendulum_inertia = p.mass * p.half_length**2 + p.inertia
        i3 = structure.floor_index[2]
        self.i3 = i3
        self.k_struct = structure.stiffness
        self.c_struct = structure.damping
        # M_s + m4 e3 e3ᵀ is constant: invert it once and solve M(q) a = Q by its Schur
        # complement (a matrix-vector product beats a triangular solve's call overhead here).
        m_const = structure.mass.copy()
        m_const[i3, i3] += self.m4
        self.m_const = m_const
        #: (M_s + m4 e3 e3ᵀ)⁻¹ and its floor-3 column w: what the Schur-complement solve of
        #: :meth:`accelerations` (and the compiled kernels) use
        self.m_const_inv = sla.inv(m_const, overwrite_a=False, check_finite=True)
        self.floor3_column = self.m_const_inv[:, i3].copy()
        self.input_matrix = np.zeros((self.n_dof, 4))
        self.input_matrix[self.floor_index, [0, 1, 2]] = 1.0
        self.input_matrix[self.phi_index, 3] = 1.0

    # --- the equations of motion -------------------------------------------------------------
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q), thesis eq. 5.57 / 5.154 in φ."""
        n = self.n_struct
        M = np.zeros((self.n_dof, self.n_dof))
        M[:n, :n] = self.m_const
        M[n, n] = self.pendulum_inertia
        M[self.i3, n] = M[n, self.i3] = self.m4 * self.l4 * np.cos(q[n])
        return M

    def forces(self, q: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Q(q, q̇, u): elastic, viscous, gravity, centrifugal and input forces (eq. 5.237)."""
        n = self.n_struct
        phi, dphi = q[n], v[n]
        sin_phi = math.sin(phi)
        Q = np.empty(self.n_dof)
        Q[:n] = -(self.k_struct @ q[:n] + self.c_struct @ v[:n])
        Q[self.floor_index] += u[:3]
        Q[self.i3] += self.m4 * self.l4 * sin_phi * dphi * dphi
        Q[n] = u[3] - self.m4 * self.g * self.l4 * sin_phi - self.r4 * dphi
        return Q

    def accelerations(self, q: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
        """q̈ = M(q)⁻¹ Q with one solve of the constant structural block (Schur complement)."""
        Q = self.forces(q, v, u)
        n = self.n_struct
        c = self.m4 * self.l4 * math.cos(q[n])
        y = self.m_const_inv @ Q[:n]
        w = self.floor3_column
        a_phi = (Q[n] - c * y[self.i3]) / (self.pendulum_inertia - c * c * w[self.i3])
        a = np.empty(self.n_dof)
        a[:n] = y - c * a_phi * w
        a[n] = a_phi
        return a

    def force_jacobians(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """∂Q/∂q and ∂Q/∂q̇ (analytic)."""
        n, i3 = self.n_struct, self.i3
        phi, dphi = q[n], v[n]
        dq = np.zeros((self.n_dof, self.n_dof))
        dv = np.zeros((self.n_dof, self.n_dof))
        dq[:n, :n] = -self.k_struct
        dv[:n, :n] = -self.c_struct
        dq[i3, n] = self.m4 * self.l4 * np.cos(phi) * dphi**2
        dv[i3, n] = 2.0 * self.m4 * self.l4 * np.sin(phi) * dphi
        dq[n, n] = -self.m4 * self.g * self.l4 * np.cos(phi)
        dv[n, n] = -self.r4
        return dq, dv

    def mass_derivative_product(self, q: np.ndarray, a: np.ndarray) -> np.ndarray:
        """∂(M(q) a)/∂q: only the coupling m4 L4 cos φ depends on q."""
        n, i3 = self.n_struct, self.i3
        d = np.zeros((self.n_dof, self.n_dof))
        s = -self.m4 * self.l4 * np.sin(q[n])
        d[i3, n] = s * a[n]
        d[n, n] = s * a[i3]
        return d

    # --- energy and linearisation ------------------------------------------------------------
    def energy(self, q: np.ndarray, v: np.ndarray) -> float:
        """Kinetic + elastic + gravitational energy, zero at rest hanging (eq. 5.50)."""
        n = self.n_struct
        kinetic = 0.5 * v @ self.mass_matrix(q) @ v
        elastic = 0.5 * q[:n] @ self.k_struct @ q[:n]
        gravity = self.m4 * self.g * self.l4 * (1.0 - np.cos(q[n]))
        return float(kinetic + elastic + gravity)

    def linearized(self) -> LinearModel:
        """Analytic linearisation about q = 0, q̇ = 0 (φ = 0: hanging)."""
        zero = np.zeros(self.n_dof)
        dq, dv = self.force_jacobians(zero, zero)
        return LinearModel(self.mass_matrix(zero), -dv, -dq, self.input_matrix.copy(),
                           self.dof_names)

    def static_fill(self, floors: np.ndarray) -> np.ndarray:
        """Structural DOFs in static equilibrium with the given floor displacements."""
        qs = np.zeros(self.n_struct)
        b = self.floor_index
        qs[b] = floors
        inner = np.setdiff1d(np.arange(self.n_struct), b)
        if inner.size:
            K = self.k_struct
            qs[inner] = -sla.solve(K[np.ix_(inner, inner)], K[np.ix_(inner, b)] @ floors)
        return qs
