"""Residual analysis of a refined model: are its one-step prediction errors white?

A model that has every mode the record resolves leaves innovations ``e(k)`` that are white
(Ljung, *System Identification*, 2nd ed. 1999, §16.6). A physical mode the order left out stays in
``e`` as a narrow-band, hence autocorrelated, component, whatever the modes found look like. The
test per output i is the portmanteau statistic of the residual analysis in Ljung §16.6 (Box &
Pierce 1970):

    ζ_i = N Σ_{τ=1..M} (R̂_i(τ) / R̂_i(0))²,    R̂_i(τ) = (1/N) Σ_k e_i(k) e_i(k - τ),

asymptotically χ²(M) when ``e_i`` is white. The record fails when the smallest p-value times the
number of outputs (Bonferroni) is below :data:`WHITENESS_LEVEL`.

Errors can be white and still carry the input: a model whose input-to-output part lacks a mode
(or an order) fits the noise model around the gap, and the estimates of the modes it has are
biased by more than any interval of theirs states. The *independence* test of the same section
catches it: per output i, the errors' cross-covariances with the past inputs,
``r̂_i = (1/N) Σ_k φ(k) e_i(k)`` with ``φ(k) = [u(k - 1), …, u(k - M)]`` (every input),

    ξ_i = N r̂_iᵀ R̂_φ⁻¹ r̂_i / λ̂_i,    R̂_φ = (1/N) Σ_k φ(k) φ(k)ᵀ,  λ̂_i = (1/N) Σ_k e_i(k)²,

asymptotically χ²(M r) when ``e_i`` is white and independent of the past inputs. Lag 0 is left
out: a controller's command answers the sample it is computed from, so on closed-loop records it
is correlated with that sample's error whatever the model; the past inputs are not (their noise
is in the errors of past samples). The record fails at the same Bonferroni-corrected level.

A missed mode whose response lies below the noise leaves no trace that any test can find. The
*signal-to-noise ratio* of each output is read off the same errors,
``10 log10((var y_i - var e_i) / var e_i)`` dB; below :data:`LOW_SNR_DB` on every output,
``identify`` says that weak modes may be hidden (a limit of the record, not of the method).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import special

Array = NDArray[np.float64]


def chi2_tail(statistic: np.ndarray, dof: int) -> np.ndarray:
    """P(χ²_dof > statistic): scipy.special's ``chdtrc``, the function ``scipy.stats.chi2.sf``
    evaluates (the same values bit for bit), without importing scipy.stats, which costs each
    process that identifies, live trackers and adaptive nodes included, a second of start-up."""
    return special.chdtrc(dof, statistic)

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
    p = float(min(1.0, m * np.min(chi2_tail(statistic, lags))))
    return Whiteness(statistic=statistic, p_value=p, lags=lags)


@dataclass(frozen=True)
class Independence:
    """The cross-correlation test of the prediction errors against the past inputs."""

    statistic: Array
    """``(m,)``: ξ_i per output."""
    p_value: float
    """Bonferroni-corrected smallest p-value over the outputs (capped at 1)."""
    lags: int

    @property
    def independent(self) -> bool:
        """Whether the errors pass as independent of the past inputs: the corrected p-value at
        least :data:`WHITENESS_LEVEL`."""
        return self.p_value >= WHITENESS_LEVEL


def independence(errors: Array, u: Array, lags: int = WHITENESS_LAGS) -> Independence:
    """Cross-correlation test (module docstring) of the prediction errors ``errors (N, m)``
    against the past inputs ``u (N, r)``; a record without inputs passes."""
    e = np.asarray(errors, dtype=float)
    u = np.asarray(u, dtype=float).reshape(len(e), -1)
    n, m = e.shape
    lags = max(1, min(lags, n // 4))
    if u.shape[1] == 0:
        return Independence(statistic=np.zeros(m), p_value=1.0, lags=lags)
    e = e - e.mean(axis=0)
    u = u - u.mean(axis=0)
    phi = np.concatenate([u[lags - k:n - k] for k in range(1, lags + 1)], axis=1)
    e = e[lags:]
    r = phi.T @ e / len(e)
    lam = np.sum(e * e, axis=0) / len(e)
    solved = np.linalg.lstsq(phi.T @ phi / len(e), r, rcond=None)[0]
    statistic = len(e) * np.sum(r * solved, axis=0) / np.where(lam > 0, lam, 1.0)
    p = float(min(1.0, m * np.min(chi2_tail(statistic, phi.shape[1]))))
    return Independence(statistic=statistic, p_value=p, lags=lags)


def snr_db(y: Array, errors: Array) -> Array:
    """``(m,)``: each output's signal-to-noise ratio in dB, taking the prediction errors as the
    noise (module docstring); -inf when they hold all of the output's variance."""
    var_y = np.var(np.asarray(y, dtype=float), axis=0)
    var_e = np.var(np.asarray(errors, dtype=float), axis=0)
    signal_var = var_y - var_e
    with np.errstate(divide="ignore"):
        return np.where(signal_var > 0, 10 * np.log10(np.maximum(signal_var, 1e-300)
                                                      / np.maximum(var_e, 1e-300)), -np.inf)


def independence_warning(test: Independence) -> str | None:
    """The sentence for a failed independence test, None for a passed one."""
    if test.independent:
        return None
    return (f"prediction errors are correlated with the past inputs (cross-correlation test over "
            f"{test.lags} lags, p = {test.p_value:.2g}): the model leaves part of the "
            "input-to-output dynamics out (a mode, or an order too few), which biases its modes")


def residual_warnings(y: Array, errors: Array, u: Array | None = None) -> list[str]:
    """One sentence per failed check of the prediction errors (whiteness, independence of the
    past inputs ``u``, SNR)."""
    found = []
    white = whiteness(errors)
    if not white.white:
        found.append(f"prediction errors are not white (portmanteau test over {white.lags} "
                     f"lags, p = {white.p_value:.2g}): the model leaves dynamics unexplained (a "
                     "mode may be missing) or the noise is coloured")
    if u is not None and (text := independence_warning(independence(errors, u))):
        found.append(text)
    best = float(np.max(snr_db(y, errors)))
    if best < LOW_SNR_DB:
        found.append(f"low signal-to-noise ratio: {best:.3g} dB on the best output (below "
                     f"{LOW_SNR_DB:g}); modes whose response is weaker than the noise cannot be "
                     "found, so a mode may be missing")
    return found
