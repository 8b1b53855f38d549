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

**Noise model.** Two model structures (Ljung §4.2): the *output-error* model, K = 0, whose
one-step prediction is the simulation from the input alone (eq. 4.25), and the *innovation form*
with K estimated, whose predictor whitens noise that the structure colours (process noise, a
noisy load cell's noise filtered by the structure, the noise a controller feeds back). Both
start from the realized model (the innovation form from OKID's observer gain, the predictor of
an ARX fit, which OKID estimates consistently in open and closed loop). The output-error model
is refined first; where its prediction errors are white (the portmanteau test of
:mod:`stillframe.identification.residual_tests`) it is the model. Otherwise the innovation form
is refined too, and the structure of lower BIC (Ljung eq. 16.33) is kept (a search that did not
converge says so, and gives no intervals):
on open-loop records both are consistent and the innovation form is the efficient one; on
closed-loop records (an input that depends on the noise) only the innovation form is (Ljung
§13.4, the direct approach), provided the outputs include what the controller measures and the
command does not act on the sample it answers (``feedthrough``).

**Stable predictor.** The prediction-error criterion is defined for models whose predictor
``A - K C`` is stable (Ljung §4.2: the model set is restricted to them). A starting observer
gain that leaves it unstable is replaced by the steady-state Kalman gain of unit noise
covariances, and a trial step that makes it unstable is refused (its residuals are
:data:`DIVERGED`). A search that ends within :data:`BOUNDARY` of that boundary has not found a
stationary point of the criterion (the record does not determine the noise model: K drifts
towards a predictor mode that the data hardly excite, as with a noise model richer than the
noise or spurious modes of an over-estimated order); it is reported as not converged.

**Covariance.** The asymptotic covariance of a prediction-error estimate (Ljung §9.3, the
``R⁻¹ Q R⁻¹`` form; a sandwich in the econometric literature):

    Cov θ ≈ (JᵀJ)⁺ S (JᵀJ)⁺ · N m / (N m - d),

with ``S`` the heteroskedasticity- and autocorrelation-consistent estimate of the covariance of
the score ``Jᵀ W e`` (Newey & West 1987, Bartlett weights; bandwidth by Andrews 1991's AR(1)
plug-in, :func:`hac_bandwidth`) and d the identifiable parameters. With white errors it reduces
to σ² (JᵀJ)⁻¹ (Ljung eq. 9.17). Frequencies, damping ratios and mode-shape phases follow by the
delta method through ``λ_c = ln(λ) / dt`` (thesis eq. 3.58); 95 % intervals are ± 1.96 standard
deviations. Intervals are stated only where the prediction errors are white and independent of
the past inputs. White: errors coloured by a lightly damped mode (a missing mode, or noise the
structure filters, left in an output-error model's errors) stay correlated over a good part of
the record, which no score covariance estimated from that record captures (on the simulated
hammer test at 128 samples, 15–75 % of such frequency intervals held the truth). Independent of
the past inputs (the cross-correlation test of :mod:`stillframe.identification.residual_tests`):
a model whose input-to-output part lacks a mode can leave white errors, and its modes are then
biased by more than their intervals state (the covariance assumes the true system in the model
set). A mode whose eigenvalue the data do not determine (its
gradient leaves the row space of J) gets no interval either, and :attr:`Refinement.notes` says
why; so does every mode of a search that did not converge.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize

from stillframe.errors import IdentificationError, InputError
from stillframe.identification.data_checks import channel_scales
from stillframe.identification.modal import ModalTable, modal_parameters
from stillframe.identification.predictor import prediction_errors
from stillframe.identification.residual_tests import independence, whiteness

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
ON_BOUNDARY = "the predictor's stability boundary"
"""The stop of a search whose predictor ended within :data:`BOUNDARY` of instability."""
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
    independent: bool = True
    """Whether the prediction errors pass as independent of the past inputs
    (:func:`stillframe.identification.residual_tests.independence`): the input-to-output part
    lacks nothing the record shows."""
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
    noise_model: str = "innovations"
    """The model kept: ``"innovations"`` (K estimated) or ``"output-error"`` (K = 0; module
    docstring, *Noise model*)."""
    G: Array = field(default_factory=lambda: np.empty((0, 0)))
    """``(n, m)``: an observer gain of the refined model, with the sign of thesis eq. 3.77
    (``A + G C`` stable): ``-K`` of the innovation form; for an output-error model (K = 0) the
    starting observer gain in the refined model's coordinates, or, where that does not make
    ``A + G C`` stable, the steady-state Kalman gain of unit noise covariances."""

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
    feedthrough: NDArray[np.bool_]
    """``(r,)``: the inputs whose column of D is a parameter (the others' is zero)."""
    innovations: bool = True
    """False: K is fixed at zero (output-error model) and not a parameter."""

    @property
    def sizes(self) -> tuple[int, ...]:
        n, m, r = self.n, self.m, self.r
        return (2 * self.pairs + self.reals, n * r, int(self.c_free.sum()),
                m * int(self.feedthrough.sum()), n * m if self.innovations else 0, n)

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
        Dfull = np.zeros((b, m, r), dtype=theta.dtype)
        Dfull[:, :, self.feedthrough] = D.reshape(b, m, -1)
        return (A, B.reshape(b, n, r), C, Dfull,
                K.reshape(b, n, m) if self.innovations else np.zeros((b, n, m), theta.dtype),
                x0)

    def pack(self, eig: Array, B: Array, C: Array, D: Array, K: Array, x0: Array) -> Array:
        """The parameters of the eigenvalues ``eig`` (``a, b`` per pair, then the real ones), B,
        C, D, K and x0."""
        gain = K.ravel() if self.innovations else np.zeros(0)
        return np.concatenate([eig, B.ravel(), C[self.c_free], D[:, self.feedthrough].ravel(),
                               gain, x0])

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
    inside = 1 - BOUNDARY
    for j in range(pairs):
        size = np.hypot(eig[2 * j], eig[2 * j + 1])
        if size >= inside:
            eig[2 * j: 2 * j + 2] *= min(1 / size**2, inside / size)
    real = eig[2 * pairs:]
    out = np.abs(real) >= inside
    real[out] = np.sign(real[out]) * np.minimum(1 / np.abs(real[out]), inside)
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


@dataclass(frozen=True)
class _Criterion:
    """The weighted one-step prediction errors of a layout's models on the normalised record,
    and their exact Jacobian (module docstring)."""

    layout: _Layout
    u: Array
    y: Array
    weight: Array

    def residuals(self, theta: Array) -> Array:
        A_, B_, C_, D_, K_, x0_ = self.layout.unpack(theta[None])
        if not (np.all(np.isfinite(theta))
                and _spectral_radius(A_[0] - K_[0] @ C_[0]) < 1):
            return np.full(self.y.size, DIVERGED)
        e = prediction_errors(A_, B_, C_, D_, K_, x0_, self.u, self.y)[0] * self.weight
        return np.where(np.abs(e) < DIVERGED, e, DIVERGED).ravel()

    def jacobian(self, theta: Array) -> Array:
        batch = theta + 1j * COMPLEX_STEP * np.eye(theta.size)
        e = prediction_errors(*self.layout.unpack(batch), self.u, self.y) * self.weight
        return (e.imag / COMPLEX_STEP).reshape(theta.size, -1).T


@dataclass(frozen=True)
class _Search:
    """Where one Levenberg–Marquardt search of the criterion ended (weighted residuals)."""

    layout: _Layout
    theta: Array
    residuals: Array
    jacobian: Array
    weight: Array
    stop: str
    converged: bool
    iterations: int
    evaluations: int
    cost_start: float

    def errors(self) -> Array:
        """``(N, m)``: the unweighted one-step prediction errors."""
        return self.residuals.reshape(-1, self.layout.m) / self.weight

    def log_det(self) -> float:
        e = self.errors()
        return float(np.linalg.slogdet(e.T @ e / e.shape[0])[1])

    def bic(self) -> float:
        return _bic(self.log_det(), _rank(self.jacobian), self.errors().shape[0])

    def model(self) -> tuple[Array, Array, Array, Array, Array, Array]:
        """A, B, C, D, K and x0."""
        A_, B_, C_, D_, K_, x0_ = self.layout.unpack(self.theta[None])
        return A_[0], B_[0], C_[0], D_[0], K_[0], x0_[0]


def _search(criterion: _Criterion, theta0: Array) -> _Search:
    """Minimise the criterion from ``theta0`` (module docstring): MINPACK's Levenberg–Marquardt,
    then :func:`_polished`."""
    fit = optimize.least_squares(criterion.residuals, theta0, jac=criterion.jacobian,
                                 method="lm", x_scale="jac", ftol=FTOL, xtol=XTOL, gtol=GTOL,
                                 max_nfev=MAX_EVALUATIONS)
    theta = (_polished(fit.x, criterion.residuals, criterion.jacobian) if fit.status > 0
             else fit.x)
    A1, _, C1, _, K1, _ = (a[0] for a in criterion.layout.unpack(theta[None]))
    stop = STOPS[fit.status]
    if _spectral_radius(A1 - K1 @ C1) > 1 - BOUNDARY:
        stop = ON_BOUNDARY
    start = criterion.residuals(theta0)
    return _Search(layout=criterion.layout, theta=theta, residuals=criterion.residuals(theta),
                   jacobian=criterion.jacobian(theta), weight=criterion.weight, stop=stop,
                   converged=stop not in (STOPS[0], ON_BOUNDARY), iterations=int(fit.njev or 0),
                   evaluations=int(fit.nfev), cost_start=float(start @ start))


def refine_prediction_error(A: Array, B: Array, C: Array, D: Array, G: Array, u: Array, y: Array,
                            dt: float, *, innovations: bool = True,
                            feedthrough: Sequence[bool] | None = None) -> Refinement:
    """Refine an OKID/ERA model ``(A, B, C, D)`` with observer gain ``G`` on the record
    ``u (N, r)``, ``y (N, m)`` by prediction-error least squares (module docstring): first the
    output-error model (K = 0, whose one-step prediction is the simulation from the input alone,
    Ljung §4.2, eq. 4.25), then, with ``innovations`` (the default) and where the output-error
    model's errors are not white, the innovation form from the realized model and ``G``; the
    noise model of least BIC is kept (module docstring, *Noise model*).
    ``feedthrough`` (default: every input) names the inputs with a direct term in D; the others'
    column of D is zero (an input computed from the same sample's outputs, as a controller's
    command, must have none: module docstring, *Noise model*)."""
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    su, sy = channel_scales(u), channel_scales(y)
    u, y = u / su, y / sy
    B, C, D = B * su[None, :], C / sy[:, None], D * su[None, :] / sy[:, None]
    n, m, r = A.shape[0], C.shape[0], B.shape[1]
    eig, Bm, Cm, Km, free, pairs, reals = real_modal_form(A, B, C, -G * sy[None, :])
    template = np.where(free, 0.0, Cm)
    direct = (np.ones(r, dtype=bool) if feedthrough is None
              else np.asarray(feedthrough, dtype=bool))
    if direct.shape != (r,):
        raise InputError(f"feedthrough names {direct.size} inputs, the record has {r}")
    layout = _Layout(n=n, m=m, r=r, pairs=pairs, reals=reals, c_template=template, c_free=free,
                     feedthrough=direct, innovations=False)
    theta0 = layout.pack(_reflected(eig, pairs), Bm, Cm, D, Km, np.zeros(n))
    e0 = prediction_errors(*layout.unpack(theta0[None]), u, y)[0]
    if not np.all(np.isfinite(e0)):
        raise IdentificationError("the starting model's simulation diverges: cannot refine")
    chosen = output_error = _search(_Criterion(layout, u, y, _weight(e0)), theta0)
    searches = [output_error]
    notes = []
    if innovations and not (output_error.converged
                            and whiteness(output_error.errors()).white):
        wide = replace(layout, innovations=True)
        start = wide.pack(_reflected(eig, pairs), Bm, Cm, D,
                          _stable_gain(layout.unpack(theta0[None])[0][0], Cm, Km), np.zeros(n))
        e1 = prediction_errors(*wide.unpack(start[None]), u, y)[0]
        full = _search(_Criterion(wide, u, y, _weight(e1)), start)
        searches.append(full)
        if full.bic() < output_error.bic():
            chosen = full
        elif not full.converged:
            notes.append(f"the innovation form's search ended at {full.stop} (the record does "
                         "not determine its noise model) and fits no better by BIC: the "
                         "output-error model (K = 0) is kept")
    evaluations = sum(search.evaluations for search in searches)
    theta, layout = chosen.theta, chosen.layout
    A1, B1, C1, D1, K1, x01 = (a[0] for a in layout.unpack(theta[None]))
    gain = -K1 if layout.innovations else -_stable_gain(A1, C1, Km)
    modes = modal_parameters(A1, C1, dt)
    cov, rank, lags, basis = _covariance(chosen.jacobian, chosen.residuals, m)
    white = whiteness(chosen.errors())
    inputs = independence(chosen.errors(), u)
    if not chosen.converged:
        notes.append(f"the refinement did not converge (stopped at {chosen.stop} after "
                     f"{evaluations} evaluations): no intervals")
    elif not white.white:
        notes.append(f"no intervals: the prediction errors are correlated (portmanteau test, p "
                     f"= {white.p_value:.2g}); the covariance of the estimate needs errors whose "
                     "correlation dies out well within the record, which a lightly damped mode's "
                     "does not")
    elif not inputs.independent:
        notes.append(f"no intervals: the prediction errors are correlated with the past inputs "
                     f"(cross-correlation test, p = {inputs.p_value:.2g}); the model leaves part "
                     "of the input-to-output dynamics out, which biases its modes by more than "
                     "an interval that assumes the model complete would state")
    stats = _mode_statistics(theta, cov, basis, layout, dt, modes,
                             intervals=chosen.converged and white.white and inputs.independent)
    notes += stats.notes
    e = chosen.errors()
    ref = Refinement(
        A=A1, B=B1, C=C1, D=D1, K=K1, x0=x01, modes=modes,
        frequency_ci_hz=np.column_stack([modes.frequency_hz - Z95 * stats.f_std,
                                         modes.frequency_hz + Z95 * stats.f_std]),
        damping_ci=np.column_stack([modes.damping_ratio - Z95 * stats.z_std,
                                    modes.damping_ratio + Z95 * stats.z_std]),
        frequency_std_hz=stats.f_std, damping_std=stats.z_std,
        cost_start=output_error.cost_start, cost=float(chosen.residuals @ chosen.residuals),
        log_det_covariance=chosen.log_det(), parameter_count=rank, errors=e,
        converged=chosen.converged, stop=chosen.stop, independent=inputs.independent,
        iterations=sum(search.iterations for search in searches),
        evaluations=evaluations, hac_lags=lags, condition=basis.condition,
        shapes=stats.shapes, shape_covariance=stats.shape_cov, output_scale=np.ones(m),
        notes=tuple(notes), noise_model="innovations" if layout.innovations else "output-error",
        G=gain)
    return in_units(ref, su, sy, dt)


def _weight(errors: Array) -> Array:
    """One weight per output: the inverse RMS of the start model's prediction errors."""
    return 1.0 / np.maximum(np.sqrt(np.mean(errors**2, axis=0)), 1e-300)


def _normalised(J: Array) -> tuple[Array, Array]:
    """J with unit columns (zero columns left zero) and the column norms."""
    norms = np.linalg.norm(J, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    return J / norms, norms


def _rank(J: Array) -> int:
    """The rank of the column-normalised Jacobian: the identifiable parameters."""
    return _rank_of(np.linalg.svd(_normalised(J)[0], compute_uv=False))


def _rank_of(singular_values: Array) -> int:
    """The singular values (descending) above :data:`RANK_TOLERANCE` of the largest."""
    s = singular_values
    return int(np.sum(s > RANK_TOLERANCE * s[0])) if s.size and s[0] > 0 else 0


def bic(refinement: Refinement, samples: int) -> float:
    """Bayesian information criterion of a refined model (Ljung §16.4, eq. 16.33 with the
    log N penalty): ``N ln det Λ̂ + d ln N``, d the identifiable parameters."""
    return _bic(refinement.log_det_covariance, refinement.parameter_count, samples)


def _bic(log_det: float, parameters: int, samples: int) -> float:
    return samples * log_det + parameters * np.log(samples)


def aic(refinement: Refinement, samples: int) -> float:
    """Akaike's criterion (Akaike 1974; Ljung §16.4): ``N ln det Λ̂ + 2 d``.
    It penalises parameters less than :func:`bic`; where the two choose different orders, the
    record does not decide between them."""
    return samples * refinement.log_det_covariance + 2.0 * refinement.parameter_count


def in_units(ref: Refinement, u_scale: Array, y_scale: Array, dt: float,
             reference: int | None = None) -> Refinement:
    """A refinement of the records ``u / u_scale``, ``y / y_scale`` in the records' units:
    ``B Su⁻¹``, ``Sy C``, ``Sy D Su⁻¹``, ``K Sy⁻¹``, ``G Sy⁻¹``, errors and shapes times Sy (the
    state, A and the eigenvalues are unchanged)."""
    return replace(
        ref, B=ref.B / u_scale[None, :], C=y_scale[:, None] * ref.C,
        D=y_scale[:, None] * ref.D / u_scale[None, :], K=ref.K / y_scale[None, :],
        G=ref.G / y_scale[None, :],
        modes=modal_parameters(ref.A, y_scale[:, None] * ref.C, dt, reference=reference),
        log_det_covariance=ref.log_det_covariance + 2 * float(np.sum(np.log(y_scale))),
        errors=ref.errors * y_scale[None, :], output_scale=ref.output_scale * y_scale)


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
    Js, norms = _normalised(J)
    _, s, vt = np.linalg.svd(Js, full_matrices=False)
    rank = _rank_of(s)
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
                     modes: ModalTable, *, intervals: bool) -> _ModeStatistics:
    """Delta-method standard deviations of each mode's frequency and damping ratio and the
    covariance of its shape, in the order of ``modes`` (matched by eigenvalue); NaN without
    ``intervals`` or where the record does not determine the mode."""
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
        if not intervals:
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
