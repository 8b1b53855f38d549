"""One entry point from sampled input/output records to an identified model and its modes.

Methods (thesis ch. 3):

- ``okid-era``: OKID observer Markov parameters (eq. 3.106), system Markov parameters (eq. 3.107),
  ERA (eq. 3.137), observer gain G by least squares from the observer gain Markov parameters
  (eqs. 3.108, 3.112);
- ``okid-eradc``: the same with ERA/DC (eq. 3.164) in place of ERA.

With ``combined=True`` the OKID methods realize the combined parameters ``[Y_k, Y^0_k]`` instead
(eqs. 3.165–3.203, the thesis's variant for the rig in §5.5), which gives B and G together; on the
simulated hammer test its damping ratios are worse (docs/identification.md), so it is not the
default.
By default the OKID model is then refined by prediction-error least squares in innovation form
(:mod:`stillframe.identification.pem`), which also gives each mode a 95 % interval and the
residual checks; ``refine=False`` is the faster path without it, which still runs every other
check and says in a warning that the model is not refined.
- ``era-impulse``: the record is the response to one pulse on a single input at the first
  sample; ``Y_k = y(k) / u(0)`` and ERA. No observer gain.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import IdentificationError, InputError
from stillframe.identification.data_checks import (
    channel_names,
    channel_scales,
    check_excitation,
    check_length,
    check_values,
    repair_absurd,
)
from stillframe.identification.era import (
    EraDimensions,
    HankelFactorization,
    auto_order,
    factorize,
    order_gap,
)
from stillframe.identification.modal import ModalTable, modal_parameters
from stillframe.identification.okid import minimum_samples, observer_gain, okid
from stillframe.identification.order_selection import refine_candidates
from stillframe.identification.pem import Refinement, in_units, refine_prediction_error
from stillframe.identification.quality import (
    left_out_modes,
    mode_consistency,
    persists,
    phase_warnings,
    quality_warnings,
    uncertain_modes,
)
from stillframe.identification.residual_tests import residual_warnings

NOT_REFINED = ("not refined: the model is OKID/ERA's without the prediction-error refinement "
               "(no 95 % intervals, no residual checks); its damping ratios are biased at low "
               "SNR")
"""The warning of every identification that skips the refinement (``refine=False`` or a method
the refinement does not apply to)."""

Array = NDArray[np.float64]
Method = Literal["okid-era", "okid-eradc", "era-impulse"]
METHODS: tuple[str, ...] = ("okid-era", "okid-eradc", "era-impulse")
NoiseModel = Literal["innovations", "output-error"]
NOISE_MODELS: tuple[str, ...] = ("innovations", "output-error")

DEFAULT_OBSERVER_ORDER = 20
PULSE_TOLERANCE = 1e-9
"""era-impulse: input samples after the first must be below this fraction of the pulse."""


@dataclass(frozen=True)
class Identification:
    """An identified discrete model, how it was obtained and its modes."""

    A: Array
    B: Array
    C: Array
    D: Array
    G: Array | None
    """Observer gain (eq. 3.77 sign: ``Abar = A + G C``); None for ``era-impulse``."""
    dt: float
    order: int
    order_gap: float
    """``sigma_n / sigma_{n+1}`` at the chosen order (the auto criterion's value)."""
    hankel_singular_values: Array
    markov: Array
    """System Markov parameters ``Y_0 .. Y_K``, ``(K + 1, m, r)``."""
    modes: ModalTable
    method: str
    observer_order: int | None
    dimensions: EraDimensions
    factorization: HankelFactorization = field(repr=False)
    """The Hankel SVD, reusable for other orders (e.g. a stabilization diagram)."""
    consistent: NDArray[np.bool_]
    """Per mode: persists at orders n + 2 and n + 4 (:mod:`stillframe.identification.quality`)."""
    warnings: tuple[str, ...]
    """The quality checks that failed (weak order gap, inconsistent, unstable, left-out or
    uncertain modes)."""
    refinement: Refinement | None = None
    """The prediction-error refinement (the default): A, B, C, D and the modes above are its; it
    holds the modes' 95 % intervals. None when not refined (``refine=False``, era-impulse,
    combined)."""


def _as_record(name: str, values: Array) -> Array:
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise InputError(f"{name} must be a non-empty (samples, channels) array, got {arr.shape}")
    return arr


def _pulse_markov(u: Array, y: Array) -> Array:
    if u.shape[1] != 1:
        raise InputError(f"era-impulse needs a single input, got {u.shape[1]}")
    pulse = u[0, 0]
    if pulse == 0 or np.max(np.abs(u[1:]), initial=0.0) > PULSE_TOLERANCE * abs(pulse):
        raise InputError(
            "era-impulse needs a single pulse at the first input sample and zeros after it; "
            "use okid-era or okid-eradc for general inputs"
        )
    return (y / pulse)[:, :, None]


def _impulse_factorization(u: Array, y: Array, order: int, alpha: int | None, beta: int | None,
                           ) -> tuple[Array, EraDimensions, HankelFactorization]:
    """Markov parameters of a pulse response, the Hankel sizes and the ERA Hankel SVD."""
    markov = _pulse_markov(u, y)
    n_samples, m = y.shape
    a = alpha or min(50, max(1, (n_samples - 2) // 5))
    b = beta or min(200, max(1, n_samples - 1 - a))
    dims = EraDimensions(alpha=a, beta=b)
    if dims.markov_count(False) > n_samples or a * m < order:
        raise IdentificationError(
            f"record of {n_samples} samples too short for order {order} with alpha={a}, "
            f"beta={b} (needs alpha*outputs >= order and alpha+beta+1 samples)"
        )
    markov = markov[: dims.markov_count(False)]
    return markov, dims, factorize(markov, dims, correlated=False)


def _observer_order(n_samples: int, r: int, m: int, order: int, requested: int | None,
                    names: list[str]) -> int:
    """OKID's p: as requested, or the default lowered to what the record allows; checked."""
    if requested is None:
        p = DEFAULT_OBSERVER_ORDER
        while p > max(1, math.ceil(order / m)) and n_samples < minimum_samples(r, m, p):
            p -= 1
    else:
        p = requested
    if p * m < order:
        raise InputError(f"observer order {p} with {m} outputs bounds the model order by "
                         f"{p * m} < {order} (thesis: m p >= n)")
    check_length(n_samples, minimum_samples(r, m, p), order, names,
                 f"OKID with observer order {p}")
    return p


def _check_request(u: Array, y: Array, dt: float, method: str, order: object,
                   max_order: int | None, combined: bool, noise_model: str) -> None:
    if u.shape[0] != y.shape[0]:
        raise InputError(f"input has {u.shape[0]} samples but output has {y.shape[0]}")
    if isinstance(dt, bool) or not (isinstance(dt, Real) and math.isfinite(dt) and dt > 0):
        raise InputError(f"sampling interval dt must be a positive number, got {dt!r}")
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if order != "auto" and (isinstance(order, bool) or not isinstance(order, Integral)
                            or order < 1):
        raise InputError(f"order must be a positive integer or 'auto', got {order!r}")
    if max_order is not None and (not isinstance(max_order, Integral) or max_order < 1):
        raise InputError(f"max order must be a positive integer, got {max_order!r}")
    if noise_model not in NOISE_MODELS:
        raise InputError(f"unknown noise model {noise_model!r}; choose one of "
                         f"{', '.join(NOISE_MODELS)}")
    if combined and method == "era-impulse":
        raise InputError("combined realization needs OKID's observer gain: not with era-impulse")


def identify(
    u: Array,
    y: Array,
    dt: float,
    method: Method = "okid-eradc",
    order: int | Literal["auto"] = "auto",
    *,
    observer_order: int | None = None,
    max_order: int | None = None,
    alpha: int | None = None,
    beta: int | None = None,
    gamma: int = 2,
    delta: int = 2,
    tau: int = 1,
    reference_sensor: int | None = None,
    combined: bool = False,
    refine: bool | None = None,
    noise_model: NoiseModel = "innovations",
    feedthrough: Sequence[bool] | None = None,
    input_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
) -> Identification:
    """Identify a discrete state-space model of order ``order`` (or the largest singular-value
    gap up to ``max_order`` when ``"auto"``; default: half the Hankel matrix's rank bound)
    from inputs ``u (N, r)`` and outputs ``y (N, m)``.

    ``observer_order`` is OKID's p (default 20, lowered to what the record allows); ``alpha`` and
    ``beta`` are the Hankel block rows and columns (defaults: p and 4 p; for era-impulse, as many
    as the record allows up to 50 and 200); ``gamma``, ``delta``, ``tau`` are the ERA/DC
    correlation sizes (eq. 3.141). ``reference_sensor`` normalises the mode shapes (default: the
    largest component). ``combined`` realizes ``[Y_k, Y^0_k]`` (eq. 3.165) for the OKID methods.
    ``refine`` (default: wherever it applies, i.e. the OKID methods without ``combined``) refines
    the model by prediction-error least squares
    (:func:`stillframe.identification.pem.refine_prediction_error`) and checks its modes'
    intervals and its prediction errors; a model that is not refined carries :data:`NOT_REFINED`
    among its warnings. ``noise_model`` is the refined model's structure: ``"innovations"``
    (default) estimates the Kalman gain K with the model and keeps K = 0 where BIC prefers it
    (white prediction errors); ``"output-error"`` fixes K = 0 (the simulation error from the
    input alone). Open-loop records may take either; on closed-loop records (the input depends
    on the noise through a controller) only the innovation form is consistent (Ljung §13.4).
    ``feedthrough`` (default: every input) names the inputs whose direct term D the refinement
    estimates; the others' is zero, as it must be for a command computed from the same sample's
    outputs (closed loop).
    ``input_names`` and ``output_names`` name the channels in the messages
    of :mod:`stillframe.identification.data_checks`, whose checks run first. Each channel is
    divided by its RMS before identifying and the model scaled back (the modes do not depend on
    the units; the Hankel singular values and Markov parameters' SVD are of the normalised data).
    Raises :class:`InputError` on a bad request, :class:`IdentificationError` on data that cannot
    be identified.
    """
    u = _as_record("input", u)
    y = _as_record("output", y)
    _check_request(u, y, dt, method, order, max_order, combined, noise_model)
    refinable = not combined and method != "era-impulse"
    if refine and not refinable:
        raise InputError("the refinement needs OKID's observer gain of the plain realization: "
                         "not with era-impulse or combined")
    refine = refinable if refine is None else bool(refine)
    dt = float(dt)
    inputs = channel_names("input", u.shape[1], input_names)
    outputs = channel_names("output", y.shape[1], output_names)
    check_values(u, inputs)
    check_values(y, outputs)
    u, u_repairs = repair_absurd(u, inputs, dt)
    y, y_repairs = repair_absurd(y, outputs, dt)
    units = _Units(channel_scales(u), channel_scales(y))
    u, y = u / units.u_scale, y / units.y_scale

    hankel = _hankel(u, y, method=method, order=2 if order == "auto" else int(order),
                     names=(inputs, outputs), observer_order=observer_order, combined=combined,
                     alpha=alpha, beta=beta, gamma=gamma, delta=delta, tau=tau)
    s = hankel.factorization.singular_values
    if order == "auto":
        chosen, gap = auto_order(s, max_order or hankel.factorization.max_rank // 2)
        if method != "era-impulse":
            check_excitation(u, chosen, inputs)
    else:
        chosen, gap = int(order), order_gap(s, int(order))
    realized = _realize(hankel, chosen, combined)
    notes: list[str] = u_repairs + y_repairs + ([] if refine else [NOT_REFINED])
    model = None
    if refine:
        model, refine_notes = _refine(realized, chosen, hankel, u, y, dt,
                                      search=order == "auto",
                                      innovations=noise_model == "innovations",
                                      feedthrough=feedthrough, reference=reference_sensor,
                                      outputs=outputs)
        notes += refine_notes
    if model is None:                       # not refined: the realization's own checks
        model = _Model.checked(realized, hankel.factorization, chosen, dt, reference_sensor)
    A, B, C, D, G = model.matrices
    C = units.output_matrix(C)
    refinement = (None if model.refinement is None
                  else units.refinement(model.refinement, dt, reference_sensor))
    return Identification(
        A=A, B=units.input_matrix(B), C=C, D=units.feedthrough(D),
        G=None if G is None else units.gain(G), dt=dt, order=model.order, order_gap=gap,
        hankel_singular_values=s, markov=units.feedthrough(hankel.markov), method=method,
        observer_order=hankel.observer_order, dimensions=hankel.dimensions,
        factorization=hankel.factorization,
        modes=(modal_parameters(A, C, dt, reference=reference_sensor) if refinement is None
               else refinement.modes),            # the shapes in the records' units
        consistent=model.consistent,
        warnings=tuple(notes + quality_warnings(model.modes, model.consistent, model.order, gap,
                                                model.left_out, model.uncertain)),
        refinement=refinement,
    )


@dataclass(frozen=True)
class _Hankel:
    """The Markov parameters of the normalised records, the Hankel sizes and SVD, and OKID's
    observer order and observer-gain Markov parameters (None for era-impulse)."""

    markov: Array
    dimensions: EraDimensions
    factorization: HankelFactorization
    observer_order: int | None
    gain_markov: Array | None


def _hankel(u: Array, y: Array, *, method: str, order: int, names: tuple[list[str], list[str]],
            observer_order: int | None, combined: bool, alpha: int | None, beta: int | None,
            gamma: int, delta: int, tau: int) -> _Hankel:
    """The Hankel matrix of the method's Markov parameters, for a model of at least ``order``,
    with the sizes of :func:`identify`."""
    if method == "era-impulse":
        markov, sizes, fac = _impulse_factorization(u, y, order, alpha, beta)
        return _Hankel(markov, sizes, fac, None, None)
    inputs, outputs = names
    (n_samples, r), m = u.shape, y.shape[1]
    correlated = method == "okid-eradc"
    p = _observer_order(n_samples, r, m, order, observer_order, [*inputs, *outputs])
    check_excitation(u, order, inputs)
    fit = okid(u, y, p)
    sizes = EraDimensions(alpha=alpha or p, beta=beta or 4 * p, gamma=gamma if correlated else 0,
                          delta=delta if correlated else 0, tau=tau)
    count = sizes.markov_count(correlated)
    markov = fit.system_markov(count)
    gain_markov = fit.observer_gain_markov(max(count, p + 1))
    params = np.concatenate([markov, gain_markov[:count]], axis=2) if combined else markov
    return _Hankel(markov, sizes, factorize(params, sizes, correlated=correlated), p,
                   gain_markov[: p + 1])


def _realize(hankel: _Hankel, order: int, combined: bool) -> tuple[Array, ...]:
    """A, B, C, D, G of the order-``order`` realization (G: None for era-impulse)."""
    real = hankel.factorization.realize(order)
    r = hankel.markov.shape[2]
    if hankel.gain_markov is None:
        B, G = real.B, None
    elif combined:
        B, G = real.B[:, :r], real.B[:, r:]  # eqs. 3.198, 3.199
    else:
        B, G = real.B, observer_gain(real.A, real.C, hankel.gain_markov)
    return real.A, B, real.C, real.D[:, :r], G  # the combined Gamma_0 is [D, 0]


@dataclass(frozen=True)
class _Model:
    """A model of the normalised records (A, B, C, D, G), its order, its modes and their
    checks; ``uncertain`` and ``refinement`` only for a refined model."""

    matrices: tuple[Array, ...]
    order: int
    modes: ModalTable
    consistent: NDArray[np.bool_]
    left_out: NDArray[np.float64]
    uncertain: NDArray[np.bool_] | None = None
    refinement: Refinement | None = None

    @classmethod
    def checked(cls, matrices: tuple[Array, ...], fac: HankelFactorization, order: int,
                dt: float, reference: int | None) -> _Model:
        """The realization's model: each mode persists at orders n + 2 and n + 4."""
        modes = modal_parameters(matrices[0], matrices[2], dt, reference=reference)
        return cls(matrices, order, modes, mode_consistency(fac, modes, order, dt),
                   left_out_modes(fac, modes, order, dt))


def _refine(realized: tuple[Array, ...], order: int, hankel: _Hankel, u: Array, y: Array,
            dt: float, *, search: bool, innovations: bool, feedthrough: Sequence[bool] | None,
            reference: int | None, outputs: list[str]) -> tuple[_Model | None, list[str]]:
    """The prediction-error refinement of the order-``order`` realization (``search``: over the
    candidate orders around it, :func:`refine_candidates`) with its checks and notes; None, with
    the reason, when the refinement cannot start."""
    fac = hankel.factorization
    choice = None
    try:
        if search:
            choice = refine_candidates(fac, hankel.gain_markov, u.shape[1], u, y, dt,
                                       order, innovations=innovations,
                                       feedthrough=feedthrough)
            refinement = choice.refinement
        else:
            refinement = refine_prediction_error(*realized, u, y, dt,
                                                 innovations=innovations,
                                                 feedthrough=feedthrough)
    except IdentificationError as exc:  # e.g. noise-free data: OKID's predictor diverges
        return None, [f"{NOT_REFINED}; the refinement could not start ({exc})"]
    order = order if choice is None else choice.order
    notes = [choice.note] if choice is not None and choice.note else []
    modes = modal_parameters(refinement.A, refinement.C, dt, reference=reference)
    if choice is not None and choice.larger is not None:
        consistent = persists(modes, choice.larger.modes)
    else:
        consistent = mode_consistency(fac, modes, order, dt)
    # a mode without an interval (withheld, and said so in the notes) is not called wide
    uncertain = (uncertain_modes(modes, refinement.frequency_ci_hz, refinement.damping_ci)
                 & np.isfinite(refinement.frequency_ci_hz).all(axis=1))
    notes += list(refinement.notes) + residual_warnings(y, refinement.errors, u)
    notes += phase_warnings(modes, refinement.phase_std(reference), outputs)
    matrices = (refinement.A, refinement.B, refinement.C, refinement.D, refinement.G)
    return _Model(matrices, order, modes, consistent, left_out_modes(fac, modes, order, dt),
                  uncertain, refinement), notes


@dataclass(frozen=True)
class _Units:
    """Maps a model identified on the normalised records ``u / u_scale``, ``y / y_scale`` back to
    the records' units: ``B Su⁻¹``, ``Sy C``, ``Sy D Su⁻¹``, ``G Sy⁻¹`` (the state and A are
    unchanged, so are the eigenvalues)."""

    u_scale: Array
    y_scale: Array

    def input_matrix(self, B: Array) -> Array:
        return B / self.u_scale[None, :]

    def output_matrix(self, C: Array) -> Array:
        return self.y_scale[:, None] * C

    def feedthrough(self, D: Array) -> Array:
        """``D`` or a stack of Markov parameters ``(..., m, r)``."""
        return self.y_scale[:, None] * D / self.u_scale[None, :]

    def gain(self, G: Array) -> Array:
        return G / self.y_scale[None, :]

    def refinement(self, ref: Refinement, dt: float, reference: int | None) -> Refinement:
        return in_units(ref, self.u_scale, self.y_scale, dt, reference)
