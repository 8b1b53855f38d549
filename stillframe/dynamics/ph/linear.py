"""Linear vibration analysis of an assembled pHDAE about a configuration at rest (seed 000 §5.3).

The constraint multipliers are removed with a null-space basis P of the velocity constraints
(eq. 47): M̂ = PᵀMP, and the stiffness seen by ν is the elastic DᵀC⁻¹D (the mixed elements'
stresses condensed) plus the linearised gravity and constraint-reaction forces. The
eigenvalues of E Φ = J Φ Λ are then ±jω with ω² the eigenvalues of (K̂, M̂).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from stillframe.dynamics.ph.system import PHSystem

FD_STEP = 1e-6


def _static_multipliers(system: PHSystem, q: np.ndarray) -> np.ndarray:
    """λ₀ balancing gravity at q with zero stresses: G_ν λ₀ = Aᵀ ∂_q V."""
    G = system.constraint_matrix(q, 0.0)[system.n_q:2 * system.n_q]
    load = system.kinematics(q).T @ system.potential_gradient(q)
    if not np.any(load):
        return np.zeros(G.shape[1])
    return np.linalg.lstsq(G, load, rcond=None)[0]


def stiffness(system: PHSystem, q: np.ndarray) -> np.ndarray:
    """Tangent stiffness in ν coordinates: DᵀC⁻¹D + ∂(AᵀV_q − G_ν λ₀)/∂q · A."""
    D, C = system.stress_coupling, system.compliance
    K = D.T @ np.linalg.solve(C, D) if C.size else np.zeros((system.n_q, system.n_q))
    lam0 = _static_multipliers(system, q)
    nq = system.n_q

    def reaction(qq: np.ndarray) -> np.ndarray:
        G = system.constraint_matrix(qq, 0.0)[nq:2 * nq]
        return system.kinematics(qq).T @ system.potential_gradient(qq) - G @ lam0

    if np.any(reaction(q)) or np.any(lam0):
        Kg = np.zeros((nq, nq))
        for i in range(nq):
            dq = np.zeros(nq)
            dq[i] = FD_STEP
            Kg[:, i] = (reaction(q + dq) - reaction(q - dq)) / (2 * FD_STEP)
        K = K + Kg @ system.kinematics(q)
    return K


def reduced_matrices(system: PHSystem, q: np.ndarray,
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Null-space basis P of the velocity constraints (ν = P ξ) and the reduced M̂, R̂, K̂
    (eq. 47): M̂ ξ̈ + R̂ ξ̇ + K̂ ξ = 0 about q at rest."""
    Dg = system.constraints(q, 0.0)[1]
    A = system.kinematics(q)
    P = sla.null_space(Dg @ A) if Dg.size else np.eye(system.n_q)
    K = P.T @ stiffness(system, q) @ P
    return P, P.T @ system.mass @ P, P.T @ system.dissipation(q) @ P, 0.5 * (K + K.T)


def natural_frequencies(system: PHSystem, q: np.ndarray, count: int | None = None,
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Pulsations ω [rad/s] (ascending) and mode shapes in ν of the system linearised at q."""
    P, Mr, _, Kr = reduced_matrices(system, q)
    w2, modes = sla.eigh(Kr, Mr)
    keep = slice(None) if count is None else slice(0, count)
    return np.sqrt(np.clip(w2, 0.0, None))[keep], (P @ modes)[:, keep]


def pencil_eigenvalues(system: PHSystem, q: np.ndarray) -> np.ndarray:
    """Finite eigenvalues s of the gravity-free pencil E Φ s = J Φ (eq. 45, §6.1), ν-σ-λ part:
    [[M,0,0],[0,C,0],[0,0,0]] s x = [[0,−Dᵀ,G],[D,0,0],[−Gᵀ,0,0]] x."""
    nq, ns = system.n_q, system.n_stress
    G = system.constraint_matrix(q, 0.0)[nq:2 * nq]
    m = G.shape[1]
    n = nq + ns + m
    E = np.zeros((n, n))
    E[:nq, :nq] = system.mass
    E[nq:nq + ns, nq:nq + ns] = system.compliance
    J = np.zeros((n, n))
    D = system.stress_coupling
    J[:nq, nq:nq + ns] = -D.T
    J[nq:nq + ns, :nq] = D
    J[:nq, nq + ns:] = G
    J[nq + ns:, :nq] = -G.T
    s = sla.eigvals(J, E)
    return s[np.isfinite(s)]
