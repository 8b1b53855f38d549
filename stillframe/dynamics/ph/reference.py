"""Reference solutions: the pHDAE reduced to index 1 and integrated by scipy's Radau.

The velocity constraint C(q) ν + g_t = 0 (C = ∂g/∂q A) is differentiated once more and
stabilised (Baumgarte, rate α): C ν̇ + Ċ ν + ġ_t + 2α(Cν + g_t) + α² g = 0. With the dynamics
M ν̇ = −Aᵀ∂_qV + J_g ν − Dᵀσ − Rν + Cᵀλ + Bu this gives a linear KKT system for (ν̇, λ) at every
right-hand-side evaluation; q̇ = Aν and C σ̇ = Dν complete an ODE in (q, ν, σ). Ċν and ġ_t are
central differences along the motion.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.integrate import solve_ivp

from stillframe.dynamics.ph.system import PHSystem
from stillframe.errors import InputError

STABILISATION = 20.0  # 1/s
_EPS = 1e-7


def index1_rhs(system: PHSystem, inputs: Callable[[float], np.ndarray] | None = None,
               ) -> Callable[[float, np.ndarray], np.ndarray]:
    nq = system.n_q
    M, Cs, D = system.mass, system.compliance, system.stress_coupling

    def velocity_map(q: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        g, Dg, rate = system.constraints(q, t)
        return g, Dg @ system.kinematics(q), rate

    def rhs(t: float, e: np.ndarray) -> np.ndarray:
        q, nu, s = system.split(e)
        A = system.kinematics(q)
        qdot = A @ nu
        force = (-A.T @ system.potential_gradient(q) + system.interconnection(e)[nq:2 * nq,
                                                                                 nq:2 * nq] @ nu
                 - D.T @ s - system.dissipation(q) @ nu)
        if system.inputs:
            force += system.input_matrix(q) @ np.asarray(inputs(t) if inputs else
                                                        np.zeros(len(system.inputs)))
        sdot = np.linalg.solve(Cs, D @ nu) if Cs.size else np.zeros(0)
        if system.n_constraints == 0:
            return np.concatenate([qdot, np.linalg.solve(M, force), sdot])
        g, C, rate = velocity_map(q, t)
        plus = velocity_map(q + _EPS * qdot, t + _EPS)
        minus = velocity_map(q - _EPS * qdot, t - _EPS)
        drift = ((plus[1] - minus[1]) @ nu + plus[2] - minus[2]) / (2 * _EPS)
        a = STABILISATION
        k = C.shape[0]
        kkt = np.block([[M, -C.T], [C, np.zeros((k, k))]])
        right = np.concatenate([force, -drift - 2 * a * (C @ nu + rate) - a * a * g])
        nudot = np.linalg.solve(kkt, right)[:nq]
        return np.concatenate([qdot, nudot, sdot])

    return rhs


def radau_reference(system: PHSystem, e0: np.ndarray, times: np.ndarray,
                    inputs: Callable[[float], np.ndarray] | None = None,
                    rtol: float = 1e-10, atol: float = 1e-12) -> np.ndarray:
    """States at ``times`` (rows) from Radau IIA on the index-1 form."""
    sol = solve_ivp(index1_rhs(system, inputs), (times[0], times[-1]), e0, method="Radau",
                    t_eval=times, rtol=rtol, atol=atol)
    if not sol.success:
        raise InputError(f"Radau reference failed: {sol.message}")
    return sol.y.T
