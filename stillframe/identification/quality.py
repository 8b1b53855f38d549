"""How far an identified model can be trusted: the checks behind the warnings of ``identify``.

ERA always returns a model of the requested order; at the extremes (a short record, a low
signal-to-noise ratio, an over-estimated order) some of its modes fit noise. Three checks, all
from the one Hankel factorization (thesis §3.6):

- **order gap**: σ_n / σ_{n+1} of the Hankel singular values at the chosen order (eq. 3.137's
  truncation). Below :data:`GAP_WARNING` the record does not single out this order;
- **consistency**: a mode is *consistent* when the realizations of order n + 2 and n + 4 each
  hold a mode within 1 % in frequency, 20 % in damping ratio and MAC 0.9 of it (a stabilization
  diagram read forwards from the chosen order). Modes fitted to noise move when the order grows.
  For a refined model the comparison is with the refined model of the next larger candidate
  order (:func:`persists`): ERA's own modes are biased at low SNR, the refined ones are not;
- **stability**: a mode with a negative damping ratio makes the model unstable, which a passive
  structure is not;
- **modes left out**: a mode that is stable (1 % frequency, 20 % damping, MAC 0.9)
  through :data:`STABLE_RUN` successive higher orders up to twice the chosen order, but has no
  counterpart within 1 % in the chosen model, is a physical candidate the order dropped;
- **uncertain modes** (with the prediction-error refinement, :mod:`stillframe.identification.pem`):
  a mode whose 95 % interval is wider than ± 1 % in frequency or ± 30 % in damping ratio is not
  known to that accuracy from this record;
- **a mode dropped by BIC** (with the refinement and ``--order auto``,
  :mod:`stillframe.identification.order_selection`): BIC keeps order n, but AIC (a smaller penalty
  per parameter, Ljung §16.4) prefers a larger candidate, whose model adds a mode that is stable and
  whose 95 % intervals are within the limits above. The record then does not decide whether that
  mode is physical.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from stillframe.identification.era import HankelFactorization
from stillframe.identification.modal import ModalTable, modal_parameters
from stillframe.identification.pem import Z95, Refinement, aic
from stillframe.identification.stabilization import matching_modes

GAP_WARNING = 15.0
"""σ_n / σ_{n+1} below this: the chosen order is weakly supported by the record."""
CONSISTENCY_STEPS = (2, 4)
STABLE_RUN = 3
"""A left-out mode must persist through this many successive higher orders (step 2)."""
FREQUENCY_CI_LIMIT, DAMPING_CI_LIMIT = 0.01, 0.30
"""Relative half-widths of the 95 % intervals beyond which a mode is called uncertain."""
FREQUENCY_TOL, DAMPING_TOL, MAC_MIN = 0.01, 0.2, 0.9
PHASE_CI_LIMIT_DEG = 45.0
"""A mode-shape phase whose 95 % interval is wider than ± this cannot tell an in-phase component
from one in quadrature: it is reported as not determined."""


def mode_consistency(factorization: HankelFactorization, modes: ModalTable, order: int,
                     dt: float) -> NDArray[np.bool_]:
    """Per mode of the order-``order`` realization: does it persist at orders n + 2 and n + 4?
    Orders beyond the Hankel matrix's numerical rank are skipped."""
    consistent = np.ones(len(modes), dtype=bool)
    for step in CONSISTENCY_STEPS:
        if order + step > factorization.numerical_rank:
            continue
        real = factorization.realize(order + step)
        _, close = matching_modes(modes, modal_parameters(real.A, real.C, dt),
                                  FREQUENCY_TOL, DAMPING_TOL, MAC_MIN)
        consistent &= close
    return consistent


def persists(modes: ModalTable, larger: ModalTable) -> NDArray[np.bool_]:
    """Per mode: does the larger model hold one within the consistency tolerances?"""
    return matching_modes(modes, larger, FREQUENCY_TOL, DAMPING_TOL, MAC_MIN)[1]


def left_out_modes(factorization: HankelFactorization, modes: ModalTable, order: int,
                   dt: float) -> NDArray[np.float64]:
    """Frequencies of the modes stable through :data:`STABLE_RUN` successive orders above
    ``order`` (up to ``2 order + 2`` and the numerical rank) that the chosen model lacks."""
    top = min(2 * order + 2, factorization.numerical_rank)
    orders = list(range(order + 2, top + 1, 2))
    tables = [modal_parameters(*_a_c(factorization, n), dt) for n in orders]
    found: list[float] = []
    for start in range(len(tables) - STABLE_RUN + 1):
        run = tables[start:start + STABLE_RUN]
        persistent = np.ones(len(run[0]), dtype=bool)
        for later in run[1:]:
            persistent &= matching_modes(run[0], later, FREQUENCY_TOL, DAMPING_TOL, MAC_MIN)[1]
        present, _ = matching_modes(run[0], modes, FREQUENCY_TOL, 1.0, 0.0)
        positive = run[0].damping_ratio > 0
        for f in run[0].frequency_hz[persistent & ~present & positive]:
            if all(abs(f - g) > FREQUENCY_TOL * f for g in found):
                found.append(float(f))
    return np.array(sorted(found))


def _a_c(factorization: HankelFactorization, order: int) -> tuple[np.ndarray, np.ndarray]:
    real = factorization.realize(order)
    return real.A, real.C


def uncertain_modes(modes: ModalTable, frequency_ci_hz: np.ndarray, damping_ci: np.ndarray
                    ) -> NDArray[np.bool_]:
    """Per mode: is its 95 % interval wider than the limits (module docstring)?"""
    f_half = 0.5 * (frequency_ci_hz[:, 1] - frequency_ci_hz[:, 0])
    z_half = 0.5 * (damping_ci[:, 1] - damping_ci[:, 0])
    return (~np.isfinite(f_half) | ~np.isfinite(z_half)
            | (f_half > FREQUENCY_CI_LIMIT * modes.frequency_hz)
            | (z_half > DAMPING_CI_LIMIT * np.abs(modes.damping_ratio)))


def phase_warnings(modes: ModalTable, phase_std: NDArray[np.float64], outputs: list[str]
                   ) -> list[str]:
    """The outputs whose mode-shape phase the record does not determine: a 95 % half-width
    beyond :data:`PHASE_CI_LIMIT_DEG` (``phase_std (m, modes)`` in rad, NaN: no interval)."""
    half = np.degrees(Z95 * phase_std)
    listed = [f"mode {k + 1} ({modes.frequency_hz[k]:.4g} Hz) at {outputs[i]} "
              f"({np.degrees(np.angle(modes.shapes[i, k])):+.0f} ± {half[i, k]:.0f} deg)"
              for k in range(half.shape[1]) for i in range(half.shape[0])
              if np.isfinite(half[i, k]) and half[i, k] > PHASE_CI_LIMIT_DEG]
    if not listed:
        return []
    return [f"mode-shape phases the record does not determine (95 % interval wider than "
            f"± {PHASE_CI_LIMIT_DEG:g} deg; the modal amplitude there is within its noise): "
            + "; ".join(listed)]


def dropped_by_bic(chosen: Refinement, larger: Refinement, samples: int) -> str | None:
    """The warning when BIC keeps ``chosen`` but AIC prefers ``larger`` and ``larger`` holds a
    credible mode that ``chosen`` lacks (module docstring); None otherwise."""
    if aic(larger, samples) >= aic(chosen, samples):
        return None
    modes = larger.modes
    present, _ = matching_modes(modes, chosen.modes, FREQUENCY_TOL, 1.0, 0.0)
    credible = (~present & (modes.damping_ratio > 0) & (modes.frequency_hz > 0)
                & ~uncertain_modes(modes, larger.frequency_ci_hz, larger.damping_ci))
    if not credible.any():
        return None
    listed = ", ".join(f"{f:.4g} Hz" for f in modes.frequency_hz[credible])
    order, other = chosen.A.shape[0], larger.A.shape[0]
    return (f"ambiguous order: BIC keeps order {order}, AIC prefers {other}, which adds a "
            f"well-determined mode at {listed} (a physical mode may have been dropped; try "
            f"--order {other})")


def quality_warnings(modes: ModalTable, consistent: NDArray[np.bool_], order: int,
                     gap: float, left_out: NDArray[np.float64] | None = None,
                     uncertain: NDArray[np.bool_] | None = None) -> list[str]:
    """One sentence per failed check; empty when the model passes them all."""
    found = []
    if left_out is not None and left_out.size:
        listed = ", ".join(f"{f:.4g} Hz" for f in left_out)
        found.append(f"ambiguous order: modes at {listed} are stable at higher orders but not in "
                     f"the order-{order} model (a physical mode may have been dropped; try a "
                     "higher --order)")
    if uncertain is not None and uncertain.any():
        listed = ", ".join(f"{f:.4g} Hz" for f in modes.frequency_hz[uncertain])
        found.append(f"uncertain modes: {listed} have 95 % intervals wider than "
                     f"{100 * FREQUENCY_CI_LIMIT:g} % in frequency or "
                     f"{100 * DAMPING_CI_LIMIT:g} % in damping")
    if np.isfinite(gap) and gap < GAP_WARNING:
        found.append(f"weak order gap: sigma_n/sigma_n+1 = {gap:.3g} at order {order} (below "
                     f"{GAP_WARNING:g}); the record does not single out this order (noise, a "
                     "short record or an over-estimated order)")
    if not consistent.all():
        listed = ", ".join(f"{f:.4g} Hz" for f in modes.frequency_hz[~consistent])
        found.append(f"inconsistent modes: {listed} change at orders {order}+2 and {order}+4 "
                     "(likely fitted to noise; the consistent ones are the physical candidates)")
    unstable = modes.damping_ratio < 0
    if unstable.any():
        listed = ", ".join(f"{f:.4g} Hz (zeta {z:.3g})" for f, z in
                           zip(modes.frequency_hz[unstable], modes.damping_ratio[unstable],
                               strict=True))
        found.append(f"unstable modes: {listed}; a passive structure has none (the record is "
                     "probably too short or too noisy)")
    return found
