"""First-order descriptor systems E(x) ẋ = f(t, x) that the integrators advance.

:class:`DescriptorSystem` is the interface: a mechanical model gives E = blockdiag(I, M(q)) and
f = [q̇, Q(q, q̇, u(t))]; a port-Hamiltonian model gives its own E and f. A singular E (algebraic
constraints) is allowed for the implicit integrators; explicit ones need ``derivative``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np
import scipy.linalg as sla

from stillframe.dynamics.models.frame import FrameModel, LinearModel

__all__ = ["DescriptorSystem", "DrivenInputs", "LinearSystem", "Load", "MechanicalSystem"]

Load = Callable[[float], np.ndarray]


class DescriptorSystem(Protocol):
    """E(x) ẋ = f(t, x)."""

    n: int

    def mass(self, x: np.ndarray) -> np.ndarray:
        """E(x)."""

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        """f(t, x)."""

    def jacobian(self, t: float, x: np.ndarray, xdot: np.ndarray) -> np.ndarray:
        """∂/∂x [f(t, x) − E(x) ẋ] at fixed ẋ (Newton matrix of the implicit integrators)."""

    def derivative(self, t: float, x: np.ndarray) -> np.ndarray:
        """ẋ = E(x)⁻¹ f(t, x) (explicit integrators; raises where E is singular)."""

    def energy(self, x: np.ndarray) -> float:
        """Stored energy, for drift checks."""


class DrivenInputs:
    """Inputs u = [f1, f2, f3, torque]: floor loads ``load(t)`` plus a held ``control``.

    ``control`` is held constant over a step (zero-order hold of a sampled controller) and is
    set between steps by the caller.
    """

    def __init__(self, load: Load | None) -> None:
        self.load = load
        self.control = np.zeros(4)

    def inputs(self, t: float) -> np.ndarray:
        """u(t) = [f1, f2, f3, torque]: the held :attr:`control` plus the floor loads ``load(t)``
        [N] on floors 1-3."""
        u = self.control.copy()
        if self.load is not None:
            u[:3] += self.load(t)
        return u


class MechanicalSystem(DrivenInputs):
    """A :class:`FrameModel` as E(x) ẋ = f(t, x) with x = [q, q̇]."""

    def __init__(self, model: FrameModel, load: Load | None = None) -> None:
        super().__init__(load)
        self.model = model
        self.n_dof = model.n_dof
        self.n = 2 * model.n_dof

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(q, q̇)``: the positions and the velocities of the state x = [q, q̇] (views, not
        copies)."""
        return x[: self.n_dof], x[self.n_dof :]

    def mass(self, x: np.ndarray) -> np.ndarray:
        """E(x) = blockdiag(I, M(q)), the descriptor matrix of the state x = [q, q̇]."""
        n = self.n_dof
        E = np.zeros((self.n, self.n))
        E[:n, :n] = np.eye(n)
        E[n:, n:] = self.model.mass_matrix(x[:n])
        return E

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        """f(t, x) = [q̇, Q(q, q̇, u(t))]: the generalized forces of the model at the inputs of
        ``t``."""
        q, v = self.split(x)
        return np.concatenate([v, self.model.forces(q, v, self.inputs(t))])

    def jacobian(self, t: float, x: np.ndarray, xdot: np.ndarray) -> np.ndarray:
        """∂/∂x [f(t, x) − E(x) ẋ] at fixed ẋ: the force Jacobians, less ∂(M(q) q̈)/∂q at the
        accelerations in ``xdot`` (the Newton matrix of the implicit integrators)."""
        n = self.n_dof
        q, v = self.split(x)
        dq, dv = self.model.force_jacobians(q, v)
        J = np.zeros((self.n, self.n))
        J[:n, n:] = np.eye(n)
        J[n:, :n] = dq - self.model.mass_derivative_product(q, xdot[n:])
        J[n:, n:] = dv
        return J

    def derivative(self, t: float, x: np.ndarray) -> np.ndarray:
        """ẋ = [q̇, M(q)⁻¹ Q(q, q̇, u(t))], for the explicit integrators."""
        q, v = self.split(x)
        return np.concatenate([v, self.model.accelerations(q, v, self.inputs(t))])

    def energy(self, x: np.ndarray) -> float:
        """The model's kinetic plus potential energy at x [J], for drift checks."""
        q, v = self.split(x)
        return self.model.energy(q, v)


class LinearSystem(DrivenInputs):
    """E ẋ = A x + B u(t) for a linearised mechanical model; ``is_linear`` lets integrators
    factor the step matrix once."""

    is_linear = True

    def __init__(self, linear: LinearModel, load: Load | None = None) -> None:
        super().__init__(load)
        n = linear.mass.shape[0]
        self.n = 2 * n
        self.n_dof = n
        self.E = np.block([[np.eye(n), np.zeros((n, n))], [np.zeros((n, n)), linear.mass]])
        self.A = np.block([[np.zeros((n, n)), np.eye(n)], [-linear.stiffness, -linear.damping]])
        self.B = np.vstack([np.zeros((n, 4)), linear.input_matrix])
        self._stiffness = linear.stiffness
        self._mass = linear.mass
        self._e_factor = sla.lu_factor(self.E)

    def mass(self, x: np.ndarray) -> np.ndarray:
        """The constant E = blockdiag(I, M)."""
        return self.E

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        """A x + B u(t)."""
        return self.A @ x + self.B @ self.inputs(t)

    def jacobian(self, t: float, x: np.ndarray, xdot: np.ndarray) -> np.ndarray:
        """The constant A: f is linear and E does not depend on x."""
        return self.A

    def derivative(self, t: float, x: np.ndarray) -> np.ndarray:
        """ẋ = E⁻¹ (A x + B u(t)), with E factored once at construction."""
        return sla.lu_solve(self._e_factor, self.rhs(t, x))

    def energy(self, x: np.ndarray) -> float:
        """½ q̇ᵀ M q̇ + ½ qᵀ K q [J], for drift checks."""
        n = self.n_dof
        q, v = x[:n], x[n:]
        return float(0.5 * v @ self._mass @ v + 0.5 * q @ self._stiffness @ q)
