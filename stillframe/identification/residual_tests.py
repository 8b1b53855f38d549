"""Residual analysis of a refined model: are its one-step prediction errors white?

A model that has every mode the record resolves leaves innovations ``e(k)`` that are white
(Ljung, *System Identification*, 2nd ed. 1999, §16.6). A physical mode the order left out stays in
``e`` as a narrow-band, hence autocorrelated, component, whatever the modes found look like. The
test per output i is the portmanteau statistic of the residual analysis in Ljung §16.6 (Box &
Pierce 1970):

    ζ_i = N Σ_{τ=1..M} (R̂_i(τ) / R̂_i(0))²,    R̂_i(τ) = (1/N) Σ_k e_i(k) e_i(k - τ),

asymptotically χ²(M) when ``e_i`` is white. The record fails when the smallest p-value times the
number of outputs (Bonferroni) is below :data:`WHITENESS_LEVEL`.

A missed mode whose response lies below the noise leaves no trace that any test can find. The
*signal-to-noise ratio* of each output is read off the same errors,
``10 log10((var y_i - var e_i) / var e_i)`` dB; below :data:`LOW_SNR_DB` on every output,
``identify`` says that weak modes may be hidden (a limit of the record, not of the method).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

Array = NDArray[np.float64]

WHITENESS_LAGS = 25
"""M: lags in the statistic (the response of a missed mode spans many samples)."""
WHITENESS_LEVEL = 0.01
"""Family-wise level of the test over the outputs."""
LOW_SNR_DB = 12.0
"""Best output's signal-to-noise ratio below which weak modes may be hidden in the noise."""


@dataclass(frozen=True)
class Whiteness:
    """The portmanteau test of the prediction errors."""

    statistic: Array
    """``(m,)``: ζ_i per output."""
    p_value: float
    """Bonferroni-corrected smallest p-value over the outputs (capped at 1)."""
    lags: int

    @property
    def white(self) -> bool:
        """Whether the errors pass as white: the corrected p-value at least
        :data:`WHITENESS_LEVEL`."""
        return self.p_value >= WHITENESS_LEVEL


def whiteness(errors: Array, lags: int = WHITENESS_LAGS) -> Whiteness:
    """Portmanteau test (module docstring) of the prediction errors ``errors (N, m)``."""
    e = np.asarray(errors, dtype=float)
    e = e - e.mean(axis=0)
    n, m = e.shape
    lags = max(1, min(lags, n // 4))
    r0 = np.sum(e * e, axis=0)
    rho = np.array([np.sum(e[k:] * e[:n - k], axis=0) for k in range(1, lags + 1)])
    statistic = n * np.sum((rho / np.where(r0 > 0, r0, 1.0)) ** 2, axis=0)
    p = float(min(1.0, m * np.min(stats.chi2.sf(statistic, lags))))
    return Whiteness(statistic=statistic, p_value=p, lags=lags)


def snr_db(y: Array, errors: Array) -> Array:
    """``(m,)``: each output's signal-to-noise ratio in dB, taking the prediction errors as the
    noise (module docstring); -inf when they hold all of the output's variance."""
    var_y = np.var(np.asarray(y, dtype=float), axis=0)
    var_e = np.var(np.asarray(errors, dtype=float), axis=0)
    signal_var = var_y - var_e
    with np.errstate(divide="ignore"):
        return np.where(signal_var > 0, 10 * np.log10(np.maximum(signal_var, 1e-300)
                                                      / np.maximum(var_e, 1e-300)), -np.inf)


def residual_warnings(y: Array, errors: Array) -> list[str]:
    """One sentence per failed check of the prediction errors (whiteness, SNR)."""
    found = []
    white = whiteness(errors)
    if not white.white:
        found.append(f"prediction errors are not white (portmanteau test over {white.lags} "
                     f"lags, p = {white.p_value:.2g}): the model leaves dynamics unexplained (a "
                     "mode may be missing) or the noise is coloured")
    best = float(np.max(snr_db(y, errors)))
    if best < LOW_SNR_DB:
        found.append(f"low signal-to-noise ratio: {best:.3g} dB on the best output (below "
                     f"{LOW_SNR_DB:g}); modes whose response is weaker than the noise cannot be "
                     "found, so a mode may be missing")
    return found
