"""Prediction-error refinement of a realized model, with the modes' covariance.

Model in innovation form (Ljung, *System Identification*, 2nd ed. 1999, §4.3, eq. 4.84):

    x(k+1) = A x(k) + B u(k) + K e(k),    y(k) = C x(k) + D u(k) + e(k),

so that the one-step predictor is (Ljung eq. 4.86)

    x̂(k+1) = (A - K C) x̂(k) + (B - K D) u(k) + K y(k),    e(k) = y(k) - C x̂(k) - D u(k).

**Scale.** The records are divided by each channel's RMS first and the model mapped back at the
end, so the search runs on numbers of order one whatever the units. The refinement minimises
``sum_k |W e(k)|^2`` (W: one weight per output, the inverse RMS of the starting model's
prediction errors) by nonlinear least squares: MINPACK's Levenberg–Marquardt (Moré 1978) through
:func:`scipy.optimize.least_squares` (``method="lm"``), with its Jacobian-column scaling of the
parameters (``x_scale="jac"``). It stops on MINPACK's scale-free criteria (:data:`FTOL`,
:data:`XTOL`, :data:`GTOL`: relative reduction of the cost, step relative to the scaled
parameters, cosine between the residual and each Jacobian column); :data:`MAX_EVALUATIONS` is a
safety bound only, and a search that reaches it is reported as not converged.

**Jacobian.** Exact to round-off by the complex step (Squire & Trapp 1998; Martins, Sturdza &
Alonso 2003): ``∂e/∂θ_j = Im e(θ + i h e_j) / h``, each column one pass of the compiled predictor
(:mod:`stillframe.identification.predictor`) in complex arithmetic. No difference quotient, so no
step to tune and no cancellation: the search sees the same gradient on any BLAS.

**Parameters.** A in real modal form — one 2 x 2 block ``[[a, b], [-b, a]]`` per complex pair
``a ± i b`` and one scalar per real eigenvalue — and B, C, D, K, x̂(0). Each mode's free complex
(or real) scale is fixed by pinning its column of C to 1 at the output where the starting mode
is largest, so the parameters are identifiable wherever the data determine the model, and the
discrete eigenvalues are parameters themselves.

**Stable predictor.** The prediction-error criterion is defined for models whose predictor
``A - K C`` is stable (Ljung §4.2: the model set is restricted to them). A starting observer
gain that leaves it unstable is replaced by the steady-state Kalman gain of unit noise
covariances, and a trial step that makes it unstable is refused (its residuals are
:data:`DIVERGED`).

**Covariance.** The asymptotic covariance of a prediction-error estimate whose errors need not be
white (Ljung §9.3, the ``R⁻¹ Q R⁻¹`` form; a sandwich in the econometric literature):

    Cov θ ≈ (JᵀJ)⁺ S (JᵀJ)⁺ · N m / (N m - d),

with ``S`` the heteroskedasticity- and autocorrelation-consistent estimate of the covariance of
the score ``Jᵀ W e`` (Newey & West 1987, Bartlett weights; bandwidth by Andrews 1991's AR(1)
plug-in, :func:`hac_bandwidth`) and d the identifiable parameters. With white errors it reduces
to σ² (JᵀJ)⁻¹ (Ljung eq. 9.17); with coloured errors (a missing mode, coloured sensor noise) it
widens the interval where σ² (JᵀJ)⁻¹ would not. Frequencies, damping ratios and mode-shape
phases follow by the delta method through ``λ_c = ln(λ) / dt`` (thesis eq. 3.58); 95 % intervals
are ± 1.96 standard deviations. A mode whose eigenvalue the data do not determine (its gradient
leaves the row space of J) gets no interval, and :attr:`Refinement.notes` says why; so does
every mode of a search that did not converge.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize

from stillframe.errors import IdentificationError
from stillframe.identification.data_checks import channel_scales
from stillframe.identification.modal import ModalTable, modal_parameters
from stillframe.identification.predictor import prediction_errors

Array = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

Z95 = 1.959963984540054
DIVERGED = 1e6
"""Weighted prediction errors beyond this (or not finite), and every error of a trial step whose
predictor is unstable, are set to this: a step the search must refuse."""
COMPLEX_STEP = 1e-20
"""Imaginary step of the complex-step Jacobian (any value far below ``sqrt(eps)`` gives the
derivative to round-off; the parameters are of order one after the scaling)."""
FTOL = 1e-15
"""MINPACK's ftol: stop when the actual and predicted relative reductions of the cost are both
below this."""
XTOL = 1e-13
"""MINPACK's xtol: stop when the step is below this share of the scaled parameter vector."""
GTOL = 1e-13
"""MINPACK's gtol: stop when the cosine between the residual vector and every Jacobian column is
below this (the gradient vanishes relative to the scales of J and of the residuals)."""
POLISH_STEPS = 3
"""Gauss–Newton steps at most after the search has converged (:func:`_polished`)."""
MAX_EVALUATIONS = 400
"""Safety bound on residual evaluations (MINPACK's maxfev); reaching it means not converged."""
STOPS = {1: "gradient (gtol)", 2: "cost reduction (ftol)", 3: "step (xtol)",
         4: "cost reduction and step (ftol, xtol)", 0: "evaluation limit"}
"""scipy's ``least_squares`` status codes, as the refinement reports them."""
BOUNDARY = 1e-6
"""A predictor whose spectral radius is within this of 1 has stopped on the stability boundary,
not at a stationary point of the criterion: not converged."""
RANK_TOLERANCE = 1e-9
"""A singular value of the column-normalised Jacobian below this share of the largest marks a
direction the record does not determine (far above the Jacobian's round-off, far below any
direction whose variance an interval could state)."""
ESTIMABLE = 1e-6
"""A quantity whose gradient has more than this share outside the row space of J is not
determined by the record: no interval."""


@dataclass(frozen=True)
class Refinement:
    """The refined innovation-form model, its fit, its modes with 95 % intervals and how the
    search ended."""

    A: Array
    B: Array
    C: Array
    D: Array
    K: Array
    x0: Array
    modes: ModalTable
    frequency_ci_hz: Array
    """``(modes, 2)``: the 95 % interval of each mode's natural frequency (NaN: none, see
    :attr:`notes`)."""
    damping_ci: Array
    """``(modes, 2)``: the 95 % interval of each mode's damping ratio (NaN: none)."""
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
    converged: bool = True
    """Whether the search stopped on a convergence criterion (not the evaluation limit)."""
    stop: str = ""
    """Which criterion stopped the search (:data:`STOPS`)."""
    iterations: int = 0
    """Jacobian evaluations (Levenberg–Marquardt iterations)."""
    evaluations: int = 0
    """Residual evaluations."""
    hac_lags: int = 0
    """Bandwidth of the score covariance (:func:`hac_bandwidth`)."""
    condition: float = 1.0
    """Condition number of the column-normalised Jacobian over its identifiable directions
    (scale-free): how much round-off in the data and the arithmetic can move the estimate."""
    shapes: ComplexArray = field(default_factory=lambda: np.empty((0, 0), complex))
    """``(m, modes)``: each mode's shape at the RMS-normalised outputs in the model's gauge
    (unnormalised), in the order of :attr:`modes`; times :attr:`output_scale` in the records'
    units. Phases are the same in both."""
    shape_covariance: Array = field(default_factory=lambda: np.empty((0, 0, 0)))
    """``(modes, 2 m, 2 m)``: covariance of ``[Re s_1, Im s_1, …, Re s_m, Im s_m]`` of each
    shape in :attr:`shapes`."""
    output_scale: Array = field(default_factory=lambda: np.empty(0))
    """``(m,)``: the outputs' RMS, from :attr:`shapes`' units to the records'."""
    notes: tuple[str, ...] = ()
    """Why an interval is missing (not converged, a mode the record does not determine)."""

    def phase_std(self, reference: int | None = None) -> Array:
        """``(m, modes)``: standard deviation [rad] of each output's mode-shape phase relative to
        the reference output (``reference``, else the largest component, as
        :func:`stillframe.identification.modal.modal_parameters` normalises); 0 at the
        reference, NaN where the mode has no interval."""
        m, k = self.shapes.shape
        out = np.full((m, k), np.nan)
        for j in range(k):
            if not np.all(np.isfinite(self.shape_covariance[j])):
                continue
            s = self.shapes[:, j]
            q = (int(np.argmax(np.abs(s) * self.output_scale)) if reference is None
                 else reference)
            for i in range(m):
                grad = np.zeros(2 * m)
                for idx, sign in ((i, 1.0), (q, -1.0)):
                    if abs(s[idx]) > 0:
                        grad[2 * idx: 2 * idx + 2] += sign * np.array(
                            [-s[idx].imag, s[idx].real]) / abs(s[idx]) ** 2
                out[i, j] = np.sqrt(max(float(grad @ self.shape_covariance[j] @ grad), 0.0))
        return out


@dataclass(frozen=True)
class _Layout:
    """Where each matrix lives in the parameter vector; C's pinned entries are not in it."""

    n: int
    m: int
    r: int
    pairs: int
    reals: int
    c_template: Array
    """``(m, n)``: C's pinned entries (1 or 0), the free ones zero."""
    c_free: NDArray[np.bool_]
    """``(m, n)``: which entries of C are parameters."""
    innovations: bool = True
    """False: K is fixed at zero (output-error model) and not a parameter."""

    @property
    def sizes(self) -> tuple[int, ...]:
        n, m, r = self.n, self.m, self.r
        return (2 * self.pairs + self.reals, n * r, int(self.c_free.sum()), m * r,
                n * m if self.innovations else 0, n)

    @property
    def size(self) -> int:
        return sum(self.sizes)

    def unpack(self, theta: Array) -> tuple[Array, Array, Array, Array, Array, Array]:
        """Batched: ``theta (b, size)`` (real or complex) to A, B, C, D, K ``(b, ., .)`` and x0
        ``(b, n)``."""
        b = theta.shape[0]
        n, m, r = self.n, self.m, self.r
        cuts = np.cumsum(self.sizes)[:-1]
        eig, B, c, D, K, x0 = np.split(theta, cuts, axis=1)
        A = np.zeros((b, n, n), dtype=theta.dtype)
        for j in range(self.pairs):
            a, w = eig[:, 2 * j], eig[:, 2 * j + 1]
            i = 2 * j
            A[:, i, i] = A[:, i + 1, i + 1] = a
            A[:, i, i + 1], A[:, i + 1, i] = w, -w
        for j in range(self.reals):
            i = 2 * self.pairs + j
            A[:, i, i] = eig[:, 2 * self.pairs + j]
        C = np.broadcast_to(self.c_template, (b, m, n)).astype(theta.dtype)
        C[:, self.c_free] = c
        return (A, B.reshape(b, n, r), C, D.reshape(b, m, r),
                K.reshape(b, n, m) if self.innovations else np.zeros((b, n, m), theta.dtype),
                x0)

    def pack(self, eig: Array, B: Array, C: Array, D: Array, K: Array, x0: Array) -> Array:
        gain = K.ravel() if self.innovations else np.zeros(0)
        return np.concatenate([eig, B.ravel(), C[self.c_free], D.ravel(), gain, x0])

    def mode_columns(self, j: int) -> list[int]:
        """The state indices of mode j (pairs first, then real eigenvalues)."""
        return [2 * j, 2 * j + 1] if j < self.pairs else [self.pairs + j]

    def eig_indices(self, j: int) -> list[int]:
        """The parameter indices of mode j's eigenvalue."""
        return [2 * j, 2 * j + 1] if j < self.pairs else [self.pairs + j]

    def c_index(self) -> NDArray[np.int_]:
        """``(m, n)``: each free entry of C's index in the parameter vector, -1 where pinned."""
        index = np.full((self.m, self.n), -1)
        index[self.c_free] = self.sizes[0] + self.sizes[1] + np.arange(int(self.c_free.sum()))
        return index


def real_modal_form(A: Array, B: Array, C: Array, K: Array
                    ) -> tuple[Array, Array, Array, Array, NDArray[np.bool_], int, int]:
    """Similarity transform to real modal form: complex pairs first (each ``[[a, b], [-b, a]]``
    from the eigenvector ``v = v_r + i v_i``: ``A [v_r v_i] = [v_r v_i] [[a, b], [-b, a]]``),
    then the real eigenvalues. Each eigenvector is scaled so that ``C v`` is exactly 1 at the
    output where it is largest (the gauge; module docstring). Returns the eigenvalue parameters,
    B, C, K, the mask of C's free entries and the counts of pairs and real eigenvalues."""
    lam, vec = np.linalg.eig(A)
    upper = [k for k in range(lam.size) if lam[k].imag > 0]
    real = [k for k in range(lam.size) if lam[k].imag == 0]
    m = C.shape[0]
    cols, eig, pins = [], [], []
    for k in (*upper, *real):
        shape = C @ vec[:, k]
        q = int(np.argmax(np.abs(shape)))
        if abs(shape[q]) == 0:
            raise IdentificationError("the realized model has a mode no output sees: "
                                      "cannot refine")
        v = vec[:, k] / shape[q]
        if lam[k].imag > 0:
            cols += [v.real, v.imag]
            eig += [lam[k].real, lam[k].imag]
            pins += [(q, 1.0), (q, 0.0)]
        else:
            cols.append(v.real)
            eig.append(lam[k].real)
            pins.append((q, 1.0))
    T = np.column_stack(cols)
    if T.shape[1] != A.shape[0] or np.linalg.cond(T) > 1e10:
        raise IdentificationError(
            "the realized A has repeated or defective eigenvalues: cannot refine")
    Tinv = np.linalg.inv(T)
    Cm = C @ T
    free = np.ones((m, A.shape[0]), dtype=bool)
    for col, (q, value) in enumerate(pins):
        Cm[q, col] = value
        free[q, col] = False
    return np.array(eig), Tinv @ B, Cm, Tinv @ K, free, len(upper), len(real)


def _polished(theta: Array, residuals: Callable[[Array], Array],
              jacobian: Callable[[Array], Array]) -> Array:
    """Gauss–Newton steps from the point where the search stopped, each kept while it lowers
    the cost, at most :data:`POLISH_STEPS`: MINPACK's step criterion can stop on a shrunken trust
    region a little short of the optimum (measured: a remaining Gauss–Newton step of 7e-11 of
    the eigenvalues), where the full step converges at once."""
    res = residuals(theta)
    cost = float(res @ res)
    for _ in range(POLISH_STEPS):
        J = jacobian(theta)
        step = np.linalg.lstsq(J, -res, rcond=RANK_TOLERANCE)[0]
        trial = theta + step
        res_t = residuals(trial)
        cost_t = float(res_t @ res_t)
        if not cost_t < cost:
            break
        theta, res, cost = trial, res_t, cost_t
    return theta


def _spectral_radius(M: Array) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(M)), initial=0.0))


def _stable_gain(A: Array, C: Array, K: Array) -> Array:
    """K if ``A - K C`` is stable, else the steady-state Kalman gain of unit process and
    measurement noise (stabilising wherever (A, C) is detectable)."""
    if _spectral_radius(A - K @ C) < 1:
        return K
    n, m = A.shape[0], C.shape[0]
    try:
        P = linalg.solve_discrete_are(A.T, C.T, np.eye(n), np.eye(m))
    except (ValueError, np.linalg.LinAlgError):
        raise IdentificationError("the starting model's predictor is unstable and no Kalman "
                                  "gain stabilises it: cannot refine") from None
    return A @ P @ C.T @ np.linalg.inv(C @ P @ C.T + np.eye(m))


def _reflected(eig: Array, pairs: int) -> Array:
    """The eigenvalue parameters with each eigenvalue outside the unit circle reflected inside
    (``λ → 1 / conj(λ)``, the same frequency): an output-error predictor is the model itself, so
    its start must be stable."""
    eig = eig.copy()
    for j in range(pairs):
        size = np.hypot(eig[2 * j], eig[2 * j + 1])
        if size >= 1:
            eig[2 * j: 2 * j + 2] /= size**2
    real = eig[2 * pairs:]
    real[np.abs(real) >= 1] = 1 / real[np.abs(real) >= 1]
    return eig


def hac_bandwidth(scores: Array) -> int:
    """Lags of the Bartlett-weighted score covariance: Andrews (1991, eq. 6.2 and §6) with an
    AR(1) fitted to each column of ``scores (N, p)``, ``1.1447 (α N)^(1/3)``, at most N / 4."""
    g = scores - scores.mean(axis=0)
    n = g.shape[0]
    num = den = 0.0
    for col in g.T:
        var0 = float(col @ col)
        if var0 == 0:
            continue
        rho = float(col[1:] @ col[:-1]) / var0
        rho = min(max(rho, -0.97), 0.97)
        sigma2 = var0 / n * (1 - rho**2)
        num += 4 * rho**2 * sigma2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += sigma2**2 / (1 - rho) ** 4
    alpha = num / den if den > 0 else 0.0
    return int(min(np.floor(1.1447 * (alpha * n) ** (1 / 3)), n // 4))


def hac_covariance(scores: Array, lags: int) -> Array:
    """``Σ_{|l| ≤ L} (1 - |l| / (L + 1)) Σ_k g_k g_{k-l}ᵀ`` of the scores ``g_k`` (rows of
    ``scores (N, p)``): Newey & West (1987)'s positive semi-definite estimate of the covariance
    of ``Σ_k g_k``."""
    S = scores.T @ scores
    for lag in range(1, lags + 1):
        gamma = scores[lag:].T @ scores[:-lag]
        S = S + (1 - lag / (lags + 1)) * (gamma + gamma.T)
    return S


def _frequency_damping_gradient(lam: complex, dt: float) -> tuple[Array, Array]:
    """Frequency [Hz] and damping ratio of the discrete eigenvalue ``lam = a + i b`` and their
    gradients ``(2, 2)`` w.r.t. ``(a, b)``."""
    lc = np.log(lam) / dt
    wn = abs(lc)
    rows = []
    for d_lam in (1.0, 1j):
        dlc = d_lam / (lam * dt)
        dwn = (lc.conjugate() * dlc).real / wn
        rows.append([dwn / (2 * np.pi), -dlc.real / wn + lc.real * dwn / wn**2])
    return np.array([wn / (2 * np.pi), -lc.real / wn]), np.array(rows).T


def refine_prediction_error(A: Array, B: Array, C: Array, D: Array, G: Array, u: Array, y: Array,
                            dt: float, *, innovations: bool = True) -> Refinement:
    """Refine an OKID/ERA model ``(A, B, C, D)`` with observer gain ``G`` on the record
    ``u (N, r)``, ``y (N, m)`` by prediction-error least squares (module docstring).
    ``innovations=False`` fixes K = 0: the output-error model, whose one-step prediction is the
    simulation from the input alone (Ljung §4.2, eq. 4.25)."""
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    su, sy = channel_scales(u), channel_scales(y)
    u, y = u / su, y / sy
    B, C, D = B * su[None, :], C / sy[:, None], D * su[None, :] / sy[:, None]
    K = -G * sy[None, :] if innovations else np.zeros((A.shape[0], y.shape[1]))
    n, m, r = A.shape[0], C.shape[0], B.shape[1]
    if innovations:
        K = _stable_gain(A, C, K)
    eig, Bm, Cm, Km, free, pairs, reals = real_modal_form(A, B, C, K)
    if not innovations:
        eig = _reflected(eig, pairs)
    template = np.where(free, 0.0, Cm)
    layout = _Layout(n=n, m=m, r=r, pairs=pairs, reals=reals, c_template=template, c_free=free,
                     innovations=innovations)
    theta0 = layout.pack(eig, Bm, Cm, D, Km, np.zeros(n))
    e0 = prediction_errors(*layout.unpack(theta0[None]), u, y)[0]
    if not np.all(np.isfinite(e0)):
        raise IdentificationError("the starting model's predictor diverges: cannot refine")
    weight = 1.0 / np.maximum(np.sqrt(np.mean(e0**2, axis=0)), 1e-300)

    def residuals(theta: Array) -> Array:
        A_, B_, C_, D_, K_, x0_ = layout.unpack(theta[None])
        if not (np.all(np.isfinite(theta))
                and _spectral_radius(A_[0] - K_[0] @ C_[0]) < 1):
            return np.full(y.size, DIVERGED)
        e = prediction_errors(A_, B_, C_, D_, K_, x0_, u, y)[0] * weight
        return np.where(np.abs(e) < DIVERGED, e, DIVERGED).ravel()

    def jacobian(theta: Array) -> Array:
        batch = theta + 1j * COMPLEX_STEP * np.eye(theta.size)
        e = prediction_errors(*layout.unpack(batch), u, y) * weight
        return (e.imag / COMPLEX_STEP).reshape(theta.size, -1).T

    fit = optimize.least_squares(residuals, theta0, jac=jacobian, method="lm", x_scale="jac",
                                 ftol=FTOL, xtol=XTOL, gtol=GTOL, max_nfev=MAX_EVALUATIONS)
    theta = _polished(fit.x, residuals, jacobian) if fit.status > 0 else fit.x
    res = residuals(theta)
    A1, B1, C1, D1, K1, x01 = (a[0] for a in layout.unpack(theta[None]))
    modes = modal_parameters(A1, C1, dt)
    cov, rank, lags, basis = _covariance(jacobian(theta), res, m)
    stop = STOPS[fit.status]
    if _spectral_radius(A1 - K1 @ C1) > 1 - BOUNDARY:
        stop = "the predictor's stability boundary"
    converged = stop != STOPS[0] and stop != "the predictor's stability boundary"
    notes = [] if converged else [f"the refinement did not converge (stopped at {stop} after "
                                  f"{fit.nfev} evaluations): no intervals"]
    stats = _mode_statistics(theta, cov, basis, layout, dt, modes, converged=converged)
    notes += stats.notes
    e = res.reshape(-1, m) / weight
    cost0 = residuals(theta0)
    ref = Refinement(
        A=A1, B=B1, C=C1, D=D1, K=K1, x0=x01, modes=modes,
        frequency_ci_hz=np.column_stack([modes.frequency_hz - Z95 * stats.f_std,
                                         modes.frequency_hz + Z95 * stats.f_std]),
        damping_ci=np.column_stack([modes.damping_ratio - Z95 * stats.z_std,
                                    modes.damping_ratio + Z95 * stats.z_std]),
        frequency_std_hz=stats.f_std, damping_std=stats.z_std,
        cost_start=float(cost0 @ cost0), cost=float(res @ res),
        log_det_covariance=float(np.linalg.slogdet(e.T @ e / e.shape[0])[1]),
        parameter_count=rank, errors=e, converged=converged, stop=stop,
        iterations=int(fit.njev or 0), evaluations=int(fit.nfev), hac_lags=lags,
        condition=basis.condition,
        shapes=stats.shapes, shape_covariance=stats.shape_cov, output_scale=np.ones(m),
        notes=tuple(notes))
    return in_units(ref, su, sy, dt)


def bic(refinement: Refinement, samples: int) -> float:
    """Bayesian information criterion of a refined model (Ljung §16.4, eq. 16.33 with the
    log N penalty): ``N ln det Λ̂ + d ln N``, d the identifiable parameters."""
    return samples * refinement.log_det_covariance + refinement.parameter_count * np.log(samples)


def aic(refinement: Refinement, samples: int) -> float:
    """Akaike's criterion (Akaike 1974; Ljung §16.4): ``N ln det Λ̂ + 2 d``.
    It penalises parameters less than :func:`bic`; where the two choose different orders, the
    record does not decide between them."""
    return samples * refinement.log_det_covariance + 2.0 * refinement.parameter_count


def in_units(ref: Refinement, u_scale: Array, y_scale: Array, dt: float,
             reference: int | None = None) -> Refinement:
    """A refinement of the records ``u / u_scale``, ``y / y_scale`` in the records' units:
    ``B Su⁻¹``, ``Sy C``, ``Sy D Su⁻¹``, ``K Sy⁻¹``, errors and shapes times Sy (the state, A and
    the eigenvalues are unchanged)."""
    return Refinement(
        A=ref.A, B=ref.B / u_scale[None, :], C=y_scale[:, None] * ref.C,
        D=y_scale[:, None] * ref.D / u_scale[None, :], K=ref.K / y_scale[None, :], x0=ref.x0,
        modes=modal_parameters(ref.A, y_scale[:, None] * ref.C, dt, reference=reference),
        frequency_ci_hz=ref.frequency_ci_hz, damping_ci=ref.damping_ci,
        frequency_std_hz=ref.frequency_std_hz, damping_std=ref.damping_std,
        cost_start=ref.cost_start, cost=ref.cost, log_det_covariance=ref.log_det_covariance
        + 2 * float(np.sum(np.log(y_scale))), parameter_count=ref.parameter_count,
        errors=ref.errors * y_scale[None, :], converged=ref.converged, stop=ref.stop,
        iterations=ref.iterations, evaluations=ref.evaluations, hac_lags=ref.hac_lags,
        condition=ref.condition,
        shapes=ref.shapes, shape_covariance=ref.shape_covariance,
        output_scale=ref.output_scale * y_scale, notes=ref.notes)


@dataclass(frozen=True)
class _RowSpace:
    """An orthonormal basis ``(p, rank)`` of the column-normalised Jacobian's row space and the
    column norms: a linear functional ``a`` of the parameters is determined by the record when
    ``a / norms`` lies in that space."""

    basis: Array
    norms: Array
    condition: float

    def determines(self, grad: Array) -> bool:
        g = grad / self.norms
        size = np.linalg.norm(g)
        return bool(size == 0 or np.linalg.norm(g - self.basis @ (self.basis.T @ g))
                    <= ESTIMABLE * size)


def _covariance(J: Array, res: Array, m: int) -> tuple[Array, int, int, _RowSpace]:
    """The sandwich covariance of the parameters (module docstring), the rank of J, the HAC
    bandwidth and J's row space."""
    norms = np.linalg.norm(J, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    Js = J / norms
    _, s, vt = np.linalg.svd(Js, full_matrices=False)
    rank = int(np.sum(s > RANK_TOLERANCE * s[0])) if s.size and s[0] > 0 else 0
    V = vt[:rank].T
    scores = (Js * res[:, None]).reshape(-1, m, Js.shape[1]).sum(axis=1)
    lags = hac_bandwidth(scores @ V)
    S = hac_covariance(scores @ V, lags) * res.size / max(res.size - rank, 1)
    inner = S / np.outer(s[:rank] ** 2, s[:rank] ** 2)
    cov_s = V @ inner @ V.T
    rows = _RowSpace(V, norms, float(s[0] / s[rank - 1]) if rank else np.inf)
    return cov_s / np.outer(norms, norms), rank, lags, rows


@dataclass(frozen=True)
class _ModeStatistics:
    f_std: Array
    z_std: Array
    shapes: ComplexArray
    shape_cov: Array
    notes: list[str]


def _mode_statistics(theta: Array, cov: Array, rows: _RowSpace, layout: _Layout, dt: float,
                     modes: ModalTable, *, converged: bool) -> _ModeStatistics:
    """Delta-method standard deviations of each mode's frequency and damping ratio and the
    covariance of its shape, in the order of ``modes`` (matched by eigenvalue); NaN where the
    search did not converge or the record does not determine the mode."""
    k = len(modes)
    f_std, z_std = np.full(k, np.nan), np.full(k, np.nan)
    shapes = np.zeros((layout.m, k), dtype=complex)
    shape_cov = np.full((k, 2 * layout.m, 2 * layout.m), np.nan)
    c_index = layout.c_index()
    C = layout.unpack(theta[None])[2][0]
    notes = []
    p = theta.size
    for j in range(layout.pairs + layout.reals):
        idx = layout.eig_indices(j)
        cols = layout.mode_columns(j)
        lam = complex(theta[idx[0]], theta[idx[1]] if len(idx) == 2 else 0.0)
        kk = int(np.argmin(np.abs(modes.eigenvalues - np.log(lam) / dt)))
        _, grad = _frequency_damping_gradient(lam, dt)
        full = np.zeros((2, p))
        full[:, idx] = grad[:, :len(idx)]
        shape = C[:, cols[0]] + (1j * C[:, cols[1]] if len(cols) == 2 else 0.0)
        shapes[:, kk] = shape
        if not converged:
            continue
        if not all(rows.determines(row) for row in full):
            notes.append(f"no interval for the mode at {modes.frequency_hz[kk]:.4g} Hz: the "
                         "record does not determine its eigenvalue")
            continue
        var = np.diag(full @ cov @ full.T)
        f_std[kk], z_std[kk] = np.sqrt(np.maximum(var, 0.0))
        sel = np.zeros((2 * layout.m, p))
        for i in range(layout.m):
            for part, col in enumerate(cols):
                if c_index[i, col] >= 0:
                    sel[2 * i + part, c_index[i, col]] = 1.0
        shape_cov[kk] = sel @ cov @ sel.T
    return _ModeStatistics(f_std, z_std, shapes, shape_cov, notes)
