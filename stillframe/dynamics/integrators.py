"""Time integration of descriptor systems behind one interface, :class:`Integrator`.

- :class:`RK4`: classical explicit Runge–Kutta, order 4, on ẋ = E⁻¹f.
- :class:`ImplicitMidpoint`: E(x_m)(x₁ − x₀) = h f(t_m, x_m), x_m = (x₀ + x₁)/2; order 2,
  A-stable, symplectic, conserves quadratic invariants (the energy of a linear undamped model)
  exactly, admits a singular E. Solved by simplified Newton: the iteration matrix
  E − (h/2)J is factored once and kept while iterations contract fast, refactored otherwise; on
  a linear system it is exact and one iteration suffices.
- :func:`reference_solution`: scipy's adaptive DOP853 or Radau at tight tolerances.

Subdivision (:class:`Subdivision`, scene keys ``integrator.max_halvings`` and
``integrator.error_limit``): a step that fails is taken again as two half steps, each of which
may be halved again, down to a floor of dt / 2^max_halvings. A step fails when the implicit
midpoint's Newton iteration does not converge, when the result is not finite, or (RK4) when the
embedded third-order estimate of the local error exceeds ``error_limit`` · (1 + |x|) in some
component: with k₅ = f(t + h, x₁), the third-order solution x̂₁ = x₀ + h/6 (k₁ + 2k₂ + 2k₃ + k₅)
differs from RK4's by h/6 (k₄ − k₅) = O(h⁴) (k₅ is the next step's k₁, first same as last).
A pendulum whipping over the top at hundreds of rad/s is physical and goes on with smaller steps;
what remains an error is a non-finite starting state or a step that still fails at the floor.
``subdivisions`` counts the halvings done.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import scipy.linalg as sla
from scipy.integrate import solve_ivp

from stillframe.dynamics.systems import DescriptorSystem, LinearSystem
from stillframe.errors import InputError, IntegrationError

__all__ = ["ADAPTIVE", "NO_SUBDIVISION", "RK4", "ImplicitMidpoint", "Integrator", "Observer",
           "StepRejected", "Subdivision", "check_finite", "floor_failure", "integrate",
           "make_integrator", "non_finite", "not_converged", "reference_solution"]


@dataclass(frozen=True)
class Subdivision:
    """When and how far a failing fixed step is split (module docstring).

    ``max_halvings``: the floor is dt / 2^max_halvings (0: a failing step is an error at once);
    ``error_limit``: RK4's local error bound relative to 1 + |x| (None: no estimate).
    """

    max_halvings: int = 12
    error_limit: float | None = 1e-5

    @classmethod
    def of(cls, section: object) -> Subdivision:
        """From a section holding ``max_halvings`` and ``error_limit`` (the scene's
        ``integrator``)."""
        return cls(max_halvings=section.max_halvings, error_limit=section.error_limit)

    @property
    def limit_code(self) -> float:
        """``error_limit`` for the compiled kernels: a negative number switches it off."""
        return -1.0 if self.error_limit is None else float(self.error_limit)


#: no subdivision and no error estimate: the bare fixed-step method
NO_SUBDIVISION = Subdivision(max_halvings=0, error_limit=None)


class StepRejected(Exception):  # noqa: N818 (a signal between step() and _step_impl, not an error)
    """Raised by ``_step_impl`` when its step failed and should be subdivided; ``cause`` is
    ``newton`` or ``error``."""

    def __init__(self, cause: str) -> None:
        super().__init__(cause)
        self.cause = cause


def floor_failure(cause: str, t: float, h: float, method: str,
                  halvings: int) -> IntegrationError:
    """The error for a step that still fails at the floor dt / 2^halvings (``h`` the floor)."""
    if cause == "newton":
        error = not_converged(t, h)
    elif cause == "error":
        error = IntegrationError(
            f"integrator.dt: the {method} error estimate still exceeds integrator.error_limit "
            f"at t = {t:.6g} s with dt = {h:g} s")
    else:
        error = non_finite(t, h, method)
    if halvings:
        error.args = (f"{error.args[0]} after {halvings} halvings of the step "
                      "(integrator.max_halvings)",)
    return error


def not_converged(t: float, h: float) -> IntegrationError:
    """The implicit midpoint's Newton iteration failed at t."""
    return IntegrationError(
        f"integrator.dt: implicit midpoint did not converge at t = {t:.6g} s with dt = {h:g} s "
        "(the motion is too fast for this step; reduce integrator.dt)")


def non_finite(t: float, h: float, method: str) -> IntegrationError:
    """The state became NaN or inf at t."""
    return IntegrationError(
        f"integrator.dt: the state became non-finite at t = {t:.6g} s with {method} at "
        f"dt = {h:g} s (beyond the method's stability limit; reduce integrator.dt or use "
        "integrator.method: midpoint)")


class Integrator(ABC):
    """One fixed step of a descriptor system E(x) ẋ = f(t, x), in the manner of scipy's
    ``OdeSolver``: :meth:`step` is the contract, :meth:`_step_impl` the method.

    Contract of ``step(system, t, x, h)``:

    - ``h > 0`` and finite, else :class:`~stillframe.errors.InputError`;
    - returns x(t + h) as a new array and never modifies ``x``;
    - a step that fails (``_step_impl`` raises :class:`StepRejected`, or returns a non-finite
      state) is subdivided as ``subdivision`` says (module docstring) and counted in
      ``subdivisions``; the result is finite, else :class:`~stillframe.errors.IntegrationError`
      naming t and the floor step (a non-finite start, or a step failing at the floor);
    - an integrator may keep state between calls (a factored iteration matrix, the previous
      increment as predictor), so one instance serves one trajectory.

    ``name`` is the ``integrator.method`` key, ``order`` the global order of accuracy,
    ``explicit`` whether it evaluates f only at known states.
    """

    name: ClassVar[str]
    order: ClassVar[int]
    explicit: ClassVar[bool]
    subdivision: Subdivision = Subdivision()
    subdivisions: int = 0

    def step(self, system: DescriptorSystem, t: float, x: np.ndarray, h: float) -> np.ndarray:
        """x(t + h) of ``system`` from ``x`` at ``t`` [s] over ``h`` [s], as a new array: the
        contract of the class docstring (``h`` checked, ``x`` finite at the start, a failed attempt
        subdivided, the result finite or an :class:`~stillframe.errors.IntegrationError`)."""
        if not (np.isfinite(h) and h > 0):
            raise InputError(f"integrator.dt: the step must be > 0 and finite, got {h!r}")
        check_finite(x, t, h, self.name)
        x1, cause = self._attempt(system, t, x, h)
        if x1 is None:
            x1 = self._subdivide(system, t, x, h, 1, cause)
        return x1

    def _attempt(self, system: DescriptorSystem, t: float, x: np.ndarray,
                 h: float) -> tuple[np.ndarray | None, str]:
        """One step, or (None, why) when it failed."""
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # checked below
                x1 = self._step_impl(system, t, x, h)
        except StepRejected as rejected:
            return None, rejected.cause
        except (ValueError, OverflowError):  # math on inf inside a model
            return None, "non-finite"
        if not np.all(np.isfinite(x1)):
            return None, "non-finite"
        return x1, ""

    def _subdivide(self, system: DescriptorSystem, t: float, x: np.ndarray, h: float,
                   depth: int, cause: str) -> np.ndarray:
        """x(t + h) as two half steps, each halved again while it fails."""
        if depth > self.subdivision.max_halvings:
            raise floor_failure(cause, t, h, self.name, depth - 1)
        self.subdivisions += 1
        half = 0.5 * h
        for start in (t, t + half):
            x1, why = self._attempt(system, start, x, half)
            x = x1 if x1 is not None else self._subdivide(system, start, x, half, depth + 1,
                                                          why)
        return x

    @abstractmethod
    def _step_impl(self, system: DescriptorSystem, t: float, x: np.ndarray,
                   h: float) -> np.ndarray:
        """x(t + h) from x(t); may return non-finite values (``step`` checks them)."""


class RK4(Integrator):
    """Classical explicit Runge–Kutta of order 4 on ẋ = E⁻¹f."""

    name = "rk4"
    order = 4
    explicit = True

    def _step_impl(self, system: DescriptorSystem, t: float, x: np.ndarray,
                   h: float) -> np.ndarray:
        f = system.derivative
        k1 = f(t, x)
        k2 = f(t + 0.5 * h, x + 0.5 * h * k1)
        k3 = f(t + 0.5 * h, x + 0.5 * h * k2)
        k4 = f(t + h, x + h * k3)
        x1 = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        limit = self.subdivision.error_limit
        if limit is not None and np.all(np.isfinite(x1)):
            error = (h / 6.0) * np.abs(k4 - f(t + h, x1))
            if np.any(error > limit * (1.0 + np.abs(x1))):
                raise StepRejected("error")
        return x1


@dataclass
class _Factor:
    lu: tuple
    h: float
    explicit_part: np.ndarray | None = None  # E + (h/2)A on a linear system


class ImplicitMidpoint(Integrator):
    """E(x_m)(x₁ − x₀) = h f(t_m, x_m), by simplified Newton (module docstring)."""

    name = "midpoint"
    order = 2
    explicit = False

    def __init__(self, tol: float = 1e-12, max_iter: int = 25, stall_tol: float = 1e-9) -> None:
        self.tol = tol
        self.stall_tol = stall_tol
        self.max_iter = max_iter
        self._factor: _Factor | None = None
        self._last_increment: np.ndarray | None = None
        self.factorizations = 0

    def _refactor(self, system: DescriptorSystem, t: float, xm: np.ndarray, xdot: np.ndarray,
                  h: float) -> None:
        matrix = system.mass(xm) - 0.5 * h * system.jacobian(t, xm, xdot)
        self._factor = _Factor(sla.lu_factor(matrix, check_finite=False), h)
        self.factorizations += 1

    def _linear_step(self, system: LinearSystem, t: float, x: np.ndarray,
                     h: float) -> np.ndarray:
        """(E − h/2 A) x₁ = (E + h/2 A) x₀ + h B u(t_m): one solve with a matrix factored once."""
        if self._factor is None or self._factor.h != h or self._factor.explicit_part is None:
            lu = sla.lu_factor(system.E - 0.5 * h * system.A, check_finite=False)
            self._factor = _Factor(lu, h, system.E + 0.5 * h * system.A)
            self.factorizations += 1
        rhs = self._factor.explicit_part @ x + h * (system.B @ system.inputs(t + 0.5 * h))
        return sla.lu_solve(self._factor.lu, rhs, check_finite=False)

    def _step_impl(self, system: DescriptorSystem, t: float, x: np.ndarray,
                   h: float) -> np.ndarray:
        if getattr(system, "is_linear", False):
            return self._linear_step(system, t, x, h)
        tm = t + 0.5 * h
        if self._factor is None or self._factor.h != h:
            self._refactor(system, tm, x, np.zeros_like(x), h)
            self._last_increment = None
        # predictor: the previous step's increment (second-order accurate guess)
        x1 = x + self._last_increment if self._last_increment is not None else x.copy()
        fresh = False
        previous = np.inf
        for _ in range(self.max_iter):
            xm = 0.5 * (x + x1)
            residual = system.mass(xm) @ (x1 - x) - h * system.rhs(tm, xm)
            delta = sla.lu_solve(self._factor.lu, residual, check_finite=False)
            x1 -= delta
            size = np.max(np.abs(delta)) / (1.0 + np.max(np.abs(x1)))
            if not np.isfinite(size):
                break
            # converged, or stalled at the residual's round-off level with a fresh matrix (a fine
            # FE mesh has h‖K‖ ≫ 1: its residual cannot resolve a relative 1e-12)
            stalled = fresh and size > 0.5 * previous and size <= self.stall_tol
            if size <= self.tol or stalled:
                self._last_increment = x1 - x
                return x1
            if size > 0.1 * previous and not fresh:
                # slow contraction: refresh the iteration matrix at the current iterate
                self._refactor(system, tm, 0.5 * (x + x1), (x1 - x) / h, h)
                fresh = True
            previous = size
        raise StepRejected("newton")


FIXED_STEP = {"rk4": RK4, "midpoint": ImplicitMidpoint}
ADAPTIVE = {"dop853": "DOP853", "radau": "Radau"}


def make_integrator(method: str, subdivision: Subdivision | None = None) -> Integrator:
    """The fixed-step integrator ``method`` subdividing as ``subdivision`` says (default:
    :class:`Subdivision`'s defaults)."""
    try:
        integrator = FIXED_STEP[method]()
    except KeyError:
        raise InputError(
            f"integrator.method: {method!r} is not a fixed-step method ({', '.join(FIXED_STEP)})"
        ) from None
    if subdivision is not None:
        integrator.subdivision = subdivision
    return integrator


def check_finite(x: np.ndarray, t: float, h: float, method: str) -> None:
    """Raise :func:`non_finite`'s :class:`~stillframe.errors.IntegrationError` (naming ``t``, ``h``
    and ``method``) unless every entry of ``x`` is finite."""
    if not np.all(np.isfinite(x)):
        raise non_finite(t, h, method)


Observer = Callable[[int, float, np.ndarray], None]


def integrate(system: DescriptorSystem, x0: np.ndarray, dt: float, n_steps: int,
              integrator: Integrator, t0: float = 0.0,
              observer: Observer | None = None) -> np.ndarray:
    """Advance ``n_steps`` fixed steps; ``observer(k, t_k, x_k)`` sees every state, k = 0..n.

    Returns the final state. Raises :class:`IntegrationError` as soon as a state is not finite.
    """
    x = np.array(x0, dtype=float)
    if observer:
        observer(0, t0, x)
    for k in range(1, n_steps + 1):
        t = t0 + (k - 1) * dt
        x = integrator.step(system, t, x, dt)
        if observer:
            observer(k, t0 + k * dt, x)
    return x


def reference_solution(system: DescriptorSystem, x0: np.ndarray, t_eval: np.ndarray,
                       method: str = "dop853", rtol: float = 1e-11,
                       atol: float = 1e-13) -> np.ndarray:
    """States at ``t_eval`` (rows) from scipy's adaptive DOP853 or Radau on ẋ = E⁻¹f."""
    try:
        scipy_method = ADAPTIVE[method]
    except KeyError:
        known = ", ".join(ADAPTIVE)
        raise InputError(f"integrator.method: {method!r} is not adaptive ({known})") from None
    sol = solve_ivp(system.derivative, (t_eval[0], t_eval[-1]), np.asarray(x0, float),
                    method=scipy_method, t_eval=t_eval, rtol=rtol, atol=atol)
    if not sol.success:
        raise IntegrationError(f"integrator.method: {method} failed: {sol.message}")
    return sol.y.T
