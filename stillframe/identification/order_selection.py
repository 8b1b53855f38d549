"""Order selection with the prediction-error refinement: the Hankel gap proposes, the
refined models' fit decides, and a disagreement between criteria is reported.

The Hankel gap (largest σ_n / σ_{n+1}, :func:`stillframe.identification.era.auto_order`) gives n.
The ERA realizations of orders n - 2, n and n + 2 (those within the Hankel matrix's numerical rank)
are each refined (:func:`stillframe.identification.pem.refine_prediction_error`), and among those
whose refinement converged (all, if none did) the order of least BIC (Ljung §16.4, eq. 16.33 with
penalty ``d ln N``) is kept: a spurious mode that the gap let in costs more parameters than it
gains in fit, a weak physical mode that the gap left out gains more. Where AIC (penalty ``2 d``)
prefers a larger candidate whose model holds a well-determined mode the kept one lacks
(:func:`stillframe.identification.quality.dropped_by_bic`), the record does not decide, and the
returned note says so. A BIC choice above the gap's order whose added modes are all uncertain (95 %
intervals beyond the limits of :func:`stillframe.identification.quality.uncertain_modes`) falls
back to the smaller candidate: those modes fit noise the record cannot resolve (on a noisy record
BIC alone can keep a spurious mode whose interval is wider than ± 30 %).

A kept model whose prediction errors are correlated with the past inputs (the independence test
of :mod:`stillframe.identification.residual_tests`) lacks part of the input-to-output dynamics,
whatever BIC says, and its modes are biased. The search then goes up, two orders at a time and
at most :data:`MAX_RAISE` above the kept order (within the Hankel matrix's numerical rank), to the
first converged model whose errors pass that test, else to the one of least BIC among those that
pass it (its modes carry no interval, but are not biased by a missing part), and the note says
so. A closed loop seen from an external excitation is such a case: the controller's and the
estimator's poles are the system's too, heavily damped, so the Hankel gap and BIC stop below
them. Where no order passes, the kept model stays and its modes carry no interval
(:func:`stillframe.identification.pem.refine_prediction_error`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import IdentificationError, InputError
from stillframe.identification.era import HankelFactorization
from stillframe.identification.okid import observer_gain
from stillframe.identification.pem import Refinement, aic, bic, refine_prediction_error
from stillframe.identification.quality import (
    FREQUENCY_TOL,
    dropped_by_bic,
    matching_modes,
    uncertain_modes,
)

Array = NDArray[np.float64]
STEPS = (-2, 0, 2)
"""Candidate orders around the Hankel gap's choice."""
MAX_RAISE = 8
"""How far above the kept order the search for a model independent of the inputs goes."""


def _complete(fits: dict[int, Refinement], order: int, fit: Callable[[int], Refinement],
              rank: int, samples: int) -> tuple[int, str | None]:
    """The kept order, raised when the kept model's errors are correlated with the past inputs
    (module docstring; refined models are added to ``fits``): to the first larger candidate
    whose errors are independent of them and whose search converged, else to the one of least
    BIC among those whose errors are independent (its modes then carry no interval, but are not
    biased by a missing part); and the note that says so (None: not raised)."""
    if fits[order].independent:
        return order, None
    complete = []
    for n in range(order + 2, min(order + MAX_RAISE, rank) + 1, 2):
        if n not in fits:
            try:
                fits[n] = fit(n)
            except (InputError, IdentificationError):
                continue
        if fits[n].independent:
            complete.append(n)
            if fits[n].converged:
                break
    if not complete:
        return order, None
    raised = (complete[-1] if fits[complete[-1]].converged
              else min(complete, key=lambda n: bic(fits[n], samples)))
    return raised, (f"order raised from {order} to {raised}: the order-{order} model's "
                    "prediction errors are correlated with the past inputs (it lacks part of "
                    "the input-to-output dynamics, as a closed loop's controller poles do)")


def only_uncertain_added(smaller: Refinement, larger: Refinement) -> bool:
    """Whether every mode ``larger`` adds to ``smaller`` (no counterpart within the frequency
    tolerance) has a 95 % interval beyond the limits (and it adds at least one)."""
    present, _ = matching_modes(larger.modes, smaller.modes, FREQUENCY_TOL, 1.0, 0.0)
    added = ~present
    doubtful = uncertain_modes(larger.modes, larger.frequency_ci_hz, larger.damping_ci)
    return bool(added.any() and np.all(doubtful[added]))


@dataclass(frozen=True)
class OrderChoice:
    """The kept order, its refined model, every candidate's BIC and the ambiguity note."""

    order: int
    refinement: Refinement
    bic: dict[int, float]
    note: str | None
    larger: Refinement | None
    """The refined model of the next larger candidate order, if any (for the consistency check
    of :func:`stillframe.identification.quality.persists`)."""


def refine_candidates(factorization: HankelFactorization, gain_markov: Array, r: int, u: Array,
                      y: Array, dt: float, hankel_order: int, *,
                      innovations: bool = True,
                      feedthrough: Sequence[bool] | None = None) -> OrderChoice:
    """Refine the candidate orders around ``hankel_order`` and keep the one of least BIC
    (module docstring). ``gain_markov`` are OKID's observer-gain Markov parameters ``(p + 1, m,
    m)`` that give each realization its observer gain; ``r`` is the number of inputs;
    ``innovations`` and ``feedthrough`` as in
    :func:`stillframe.identification.pem.refine_prediction_error`."""
    samples = u.shape[0]
    fits: dict[int, Refinement] = {}

    def _fit(n: int) -> Refinement:
        real = factorization.realize(n)
        gain = observer_gain(real.A, real.C, gain_markov)
        return refine_prediction_error(real.A, real.B[:, :r], real.C, real.D[:, :r], gain, u, y,
                                       dt, innovations=innovations, feedthrough=feedthrough)

    for step in STEPS:
        n = hankel_order + step
        if not 1 <= n <= factorization.numerical_rank:
            continue
        try:
            fits[n] = _fit(n)
        except InputError:
            if n == hankel_order:
                raise
    scores = {n: bic(fit, samples) for n, fit in fits.items()}
    converged = [n for n, fit in fits.items() if fit.converged] or list(fits)
    order = min(converged, key=scores.__getitem__)
    while order > hankel_order and order - 2 in fits and only_uncertain_added(
            fits[order - 2], fits[order]):
        order -= 2
    order, raised = _complete(fits, order, _fit, factorization.numerical_rank, samples)
    scores.update({n: bic(fits[n], samples) for n in fits.keys() - scores.keys()})
    notes = [raised] if raised else []
    notes += [dropped_by_bic(fits[order], fits[n], samples) for n in sorted(fits) if n > order
              and aic(fits[n], samples) < aic(fits[order], samples)]
    larger = [n for n in sorted(fits) if n > order]
    return OrderChoice(order=order, refinement=fits[order], bic=scores,
                       note=next((note for note in notes if note), None),
                       larger=fits[larger[0]] if larger else None)
