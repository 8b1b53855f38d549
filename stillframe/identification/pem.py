"""Prediction-error refinement of a realized model, with the modes' covariance.

Model in innovation form (Ljung, *System Identification*, 2nd ed. 1999, §4.3, eq. 4.84):

    x(k+1) = A x(k) + B u(k) + K e(k),    y(k) = C x(k) + D u(k) + e(k),

so that the one-step predictor is (Ljung eq. 4.86)

    x̂(k+1) = (A - K C) x̂(k) + (B - K D) u(k) + K y(k),    e(k) = y(k) - C x̂(k) - D u(k).

The refinement minimises ``sum_k |W e(k)|^2`` (W: one weight per output, the inverse RMS of the
starting model's prediction errors) over the parameters by nonlinear least squares
(Gauss–Newton with Levenberg–Marquardt damping; Ljung §7.2, §10.2), starting from the
OKID/ERA realization (A, B, C, D) with K = -G (OKID's observer gain, thesis eq. 3.77 sign).

Parameters: A in real modal form — one 2 x 2 block ``[[a, b], [-b, a]]`` per complex pair
``a ± i b`` and one scalar per real eigenvalue — and B, C, D, K, x̂(0) in full. The modal form
keeps the discrete eigenvalues as parameters, so their covariance is read directly off the
asymptotic covariance of the estimate (Ljung §9.3, eq. 9.17 with the Gauss–Newton Hessian):

    Cov θ ≈ σ² (Jᵀ J)⁺,    σ² = |W e|² / (N m - rank J),

the pseudo-inverse because the modal form still leaves each block's complex scaling free (the
eigenvalues do not move along those directions, so their variance is unaffected). Frequencies and
damping ratios follow by the delta method through ``λ_c = ln(λ) / dt`` (thesis eq. 3.58); the 95 %
interval is ± 1.96 standard deviations.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import IdentificationError
from stillframe.identification.modal import ModalTable, modal_parameters
from stillframe.identification.predictor import prediction_errors

Array = NDArray[np.float64]

Z95 = 1.959963984540054
DIVERGED = 1e6
"""Weighted prediction errors beyond this (or not finite) are clipped: a diverging trial step."""
FD_STEP = 1e-7
"""Relative forward-difference step of the Jacobian."""
MAX_ITERATIONS = 25
"""Gauss–Newton steps at most (each costs one batched pass over the record for the Jacobian)."""
STALL = 0.5
"""The search stops when a step lowers the cost by less than this many residual variances
``σ² = cost / (N m)``: the optimum is then closer than about ``sqrt(STALL)`` standard deviations
along the step (the cost rises by σ² one standard deviation away, Ljung §9.3)."""


@dataclass(frozen=True)
class Refinement:
    """The refined innovation-form model, its fit and its modes with 95 % intervals."""

    A: Array
    B: Array
    C: Array
    D: Array
    K: Array
    x0: Array
    modes: ModalTable
    frequency_ci_hz: Array
    """``(modes, 2)``: the 95 % interval of each mode's natural frequency."""
    damping_ci: Array
    """``(modes, 2)``: the 95 % interval of each mode's damping ratio."""
    frequency_std_hz: Array
    damping_std: Array
    cost_start: float
    cost: float
    """Weighted sum of squared one-step prediction errors, before and after."""
    log_det_covariance: float
    """``ln det`` of the innovations' sample covariance (for order selection)."""
    parameter_count: int
    """Rank of the Jacobian: the identifiable parameters."""
    errors: Array
    """``(N, m)``: the one-step prediction errors of the refined model (unweighted)."""


@dataclass(frozen=True)
class _Layout:
    """Where each matrix lives in the parameter vector."""

    n: int
    m: int
    r: int
    pairs: int
    reals: int
    innovations: bool = True
    """False: K is fixed at zero (output-error model) and not a parameter."""

    @property
    def sizes(self) -> tuple[int, ...]:
        n, m, r = self.n, self.m, self.r
        return (2 * self.pairs + self.reals, n * r, m * n, m * r,
                n * m if self.innovations else 0, n)

    @property
    def size(self) -> int:
        return sum(self.sizes)

    def unpack(self, theta: Array) -> tuple[Array, Array, Array, Array, Array, Array]:
        """Batched: ``theta (b, size)`` to A, B, C, D, K ``(b, ., .)`` and x0 ``(b, n)``."""
        b = theta.shape[0]
        n, m, r = self.n, self.m, self.r
        cuts = np.cumsum(self.sizes)[:-1]
        eig, B, C, D, K, x0 = np.split(theta, cuts, axis=1)
        A = np.zeros((b, n, n))
        for j in range(self.pairs):
            a, w = eig[:, 2 * j], eig[:, 2 * j + 1]
            i = 2 * j
            A[:, i, i] = A[:, i + 1, i + 1] = a
            A[:, i, i + 1], A[:, i + 1, i] = w, -w
        for j in range(self.reals):
            i = 2 * self.pairs + j
            A[:, i, i] = eig[:, 2 * self.pairs + j]
        return (A, B.reshape(b, n, r), C.reshape(b, m, n), D.reshape(b, m, r),
                K.reshape(b, n, m) if self.innovations else np.zeros((b, n, m)), x0)


def real_modal_form(A: Array, B: Array, C: Array, K: Array) -> tuple[Array, Array, Array, Array,
                                                                        int, int]:
    """Similarity transform to real modal form: complex pairs first (each ``[[a, b], [-b, a]]``
    from the eigenvector ``v = v_r + i v_i``: ``A [v_r v_i] = [v_r v_i] [[a, b], [-b, a]]``),
    then the real eigenvalues. Returns the eigenvalue parameters, B, C, K and the counts."""
    lam, vec = np.linalg.eig(A)
    upper = [k for k in range(lam.size) if lam[k].imag > 0]
    real = [k for k in range(lam.size) if lam[k].imag == 0]
    cols, eig = [], []
    for k in upper:
        cols += [vec[:, k].real, vec[:, k].imag]
        eig += [lam[k].real, lam[k].imag]
    for k in real:
        cols.append(vec[:, k].real)
        eig.append(lam[k].real)
    T = np.column_stack(cols)
    if T.shape[1] != A.shape[0] or np.linalg.cond(T) > 1e10:
        raise IdentificationError(
            "the realized A has repeated or defective eigenvalues: cannot refine")
    Tinv = np.linalg.inv(T)
    return np.array(eig), Tinv @ B, C @ T, Tinv @ K, len(upper), len(real)


def _predict(layout: _Layout, theta: Array, u: Array, y: Array) -> Array:
    """One-step prediction errors ``e (b, N, m)`` of each parameter vector in ``theta (b, .)``."""
    A, B, C, D, K, x0 = layout.unpack(theta)
    return prediction_errors(A, B, C, D, K, x0, u, y)


def _levenberg_marquardt(residuals: Callable[[Array], Array],
                         jacobian: Callable[[Array], Array], theta: Array, scale: Array
                         ) -> Array:
    """Minimise ``|residuals(θ)|²`` by Gauss–Newton steps with Levenberg–Marquardt damping on
    the normal equations (Ljung §10.2; Marquardt 1963): ``(JᵀJ + μ diag JᵀJ) δ = -Jᵀε`` in the
    scaled parameters ``θ / scale``; μ shrinks after a step that lowers the cost and grows until
    one does. Stops after :data:`MAX_ITERATIONS` steps or when the cost stalls."""
    res = residuals(theta)
    cost = float(res @ res)
    mu = 1e-3
    for _ in range(MAX_ITERATIONS):
        J = jacobian(theta) * scale
        H, g = J.T @ J, J.T @ res
        diag = np.maximum(np.diag(H), 1e-12 * max(float(np.max(np.diag(H))), 1e-300))
        while mu < 1e12:
            try:
                step = np.linalg.solve(H + mu * np.diag(diag), -g)
            except np.linalg.LinAlgError:
                mu *= 10
                continue
            trial = theta + scale * step
            res_t = residuals(trial)
            cost_t = float(res_t @ res_t)
            if cost_t < cost:
                break
            mu *= 10
        else:
            break
        decrease = cost - cost_t
        theta, res, cost, mu = trial, res_t, cost_t, max(mu / 10, 1e-12)
        if decrease < STALL * cost / res.size:
            break
    return theta


def refine_prediction_error(A: Array, B: Array, C: Array, D: Array, G: Array, u: Array, y: Array,
                            dt: float, innovations: bool = True) -> Refinement:
    """Refine an OKID/ERA model ``(A, B, C, D)`` with observer gain ``G`` on the record
    ``u (N, r)``, ``y (N, m)`` by prediction-error least squares (module docstring).
    ``innovations=False`` fixes K = 0: the output-error model, whose one-step prediction is the
    simulation from the input alone (Ljung §4.2, eq. 4.25)."""
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    n, m, r = A.shape[0], C.shape[0], B.shape[1]
    eig, Bm, Cm, Km, pairs, reals = real_modal_form(A, B, C, -G)
    layout = _Layout(n=n, m=m, r=r, pairs=pairs, reals=reals, innovations=innovations)
    gain = Km.ravel() if innovations else np.zeros(0)
    theta0 = np.concatenate([eig, Bm.ravel(), Cm.ravel(), D.ravel(), gain, np.zeros(n)])
    e0 = _predict(layout, theta0[None], u, y)[0]
    if not np.all(np.isfinite(e0)):
        raise IdentificationError("the starting model's predictor diverges: cannot refine")
    weight = 1.0 / np.maximum(np.sqrt(np.mean(e0**2, axis=0)), 1e-300)
    scale = np.maximum(np.abs(theta0), 1e-3)

    def residuals(theta: Array) -> Array:
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging trial step
            e = _predict(layout, theta[None], u, y)[0] * weight
        return np.where(np.abs(e) < DIVERGED, e, DIVERGED).ravel()

    def jacobian(theta: Array) -> Array:
        steps = FD_STEP * scale
        batch = np.vstack([theta, theta + np.diag(steps)])
        with np.errstate(over="ignore", invalid="ignore"):
            e = _predict(layout, batch, u, y) * weight
        e = np.where(np.abs(e) < DIVERGED, e, DIVERGED).reshape(batch.shape[0], -1)
        return ((e[1:] - e[0]) / steps[:, None]).T

    theta = _levenberg_marquardt(residuals, jacobian, theta0, scale)
    res = residuals(theta)
    J = jacobian(theta)
    H = J.T @ J
    singular = np.sqrt(np.maximum(np.linalg.eigvalsh(H), 0.0))  # of J
    rank = int(np.sum(singular > singular.max() * max(J.shape) * np.finfo(float).eps))
    sigma2 = float(res @ res) / max(res.size - rank, 1)
    cov = sigma2 * np.linalg.pinv(H, hermitian=True)
    A1, B1, C1, D1, K1, x01 = (a[0] for a in layout.unpack(theta[None]))
    e = res.reshape(-1, m) / weight
    modes = modal_parameters(A1, C1, dt)
    f_std, z_std = _modal_std(theta, cov, layout, dt, modes)
    return Refinement(
        A=A1, B=B1, C=C1, D=D1, K=K1, x0=x01, modes=modes,
        frequency_ci_hz=np.column_stack([modes.frequency_hz - Z95 * f_std,
                                         modes.frequency_hz + Z95 * f_std]),
        damping_ci=np.column_stack([modes.damping_ratio - Z95 * z_std,
                                    modes.damping_ratio + Z95 * z_std]),
        frequency_std_hz=f_std, damping_std=z_std,
        cost_start=float(residuals(theta0) @ residuals(theta0)), cost=float(res @ res),
        log_det_covariance=float(np.linalg.slogdet(e.T @ e / e.shape[0])[1]),
        parameter_count=rank, errors=e,
    )


def bic(refinement: Refinement, samples: int) -> float:
    """Bayesian information criterion of a refined model (Ljung §16.4, eq. 16.33 with the
    log N penalty): ``N ln det Λ̂ + d ln N``, d the identifiable parameters."""
    return samples * refinement.log_det_covariance + refinement.parameter_count * np.log(samples)


def aic(refinement: Refinement, samples: int) -> float:
    """Akaike's criterion (Akaike 1974; Ljung §16.4): ``N ln det Λ̂ + 2 d``.
    It penalises parameters less than :func:`bic`; where the two choose different orders, the
    record does not decide between them."""
    return samples * refinement.log_det_covariance + 2.0 * refinement.parameter_count


def _frequency_damping(a: float, b: float, dt: float) -> Array:
    lam = np.log(complex(a, b)) / dt
    wn = abs(lam)
    return np.array([wn / (2 * np.pi), -lam.real / wn])


def _modal_std(theta: Array, cov: Array, layout: _Layout, dt: float, modes: ModalTable
               ) -> tuple[Array, Array]:
    """Delta-method standard deviations of each mode's frequency and damping ratio, in the
    order of ``modes`` (matched by eigenvalue)."""
    f_std = np.zeros(len(modes))
    z_std = np.zeros(len(modes))
    for j in range(layout.pairs + layout.reals):
        idx = [2 * j, 2 * j + 1] if j < layout.pairs else [layout.pairs + j]
        a = theta[idx[0]]
        b = theta[idx[1]] if j < layout.pairs else 0.0
        if b < 0:
            continue
        base = _frequency_damping(a, b, dt)
        grad = np.empty((2, len(idx)))
        for c, i in enumerate(idx):
            h = 1e-7 * max(abs(theta[i]), 1e-3)
            shifted = [a + h, b] if c == 0 else [a, b + h]
            grad[:, c] = (_frequency_damping(*shifted, dt) - base) / h
        var = np.diag(grad @ cov[np.ix_(idx, idx)] @ grad.T)
        k = int(np.argmin(np.abs(modes.frequency_hz - base[0])
                          + np.abs(modes.damping_ratio - base[1])))
        f_std[k], z_std[k] = np.sqrt(np.maximum(var, 0.0))
    return f_std, z_std
