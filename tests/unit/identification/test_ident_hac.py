"""The score covariance behind the refinement's intervals (:mod:`stillframe.identification.pem`)
against an independent source: statsmodels' Newey–West estimate (``S_hac_simple``, its OLS
``HAC`` covariance) and, for Andrews' bandwidth, the closed form of an AR(1) score."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal
from statsmodels.regression.linear_model import OLS
from statsmodels.stats.sandwich_covariance import S_hac_simple

from stillframe.identification.pem import _covariance, hac_bandwidth, hac_covariance


def ar1(rho: float, samples: int, columns: int, seed: int) -> np.ndarray:
    """Independent AR(1) series ``g(k) = rho g(k - 1) + w(k)``, unit innovations, no start-up
    transient (the first sample drawn from the stationary law)."""
    rng = np.random.default_rng(seed)
    w = rng.standard_normal((samples, columns))
    w[0] /= np.sqrt(1 - rho**2)
    return signal.lfilter([1.0], [1.0, -rho], w, axis=0)


@pytest.mark.parametrize("lags", [0, 1, 7, 40])
def test_hac_covariance_is_statsmodels_newey_west(lags: int) -> None:
    """The same Bartlett-weighted sum as statsmodels' ``S_hac_simple`` (a second
    implementation): both sum the same products, so they agree to the round-off of summing
    4000 products of order one, far below 1e-12 of the result."""
    scores = ar1(0.6, 4000, 3, 0) @ np.array([[1.0, 0.3, 0.0], [0.0, 1.0, -0.5], [0.2, 0.0, 1.0]])
    ours = hac_covariance(scores, lags)
    theirs = S_hac_simple(scores, nlags=lags)
    np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-12 * np.abs(theirs).max())


@pytest.mark.parametrize("rho", [0.3, 0.6, 0.85])
def test_andrews_bandwidth_of_an_ar1_score(rho: float) -> None:
    """Andrews (1991, eq. 6.4) for the Bartlett kernel with AR(1) columns of one coefficient
    rho: alpha = 4 rho² / ((1 - rho)² (1 + rho)²) and the bandwidth 1.1447 (alpha N)^(1/3). The
    estimate uses the sample rho, whose standard error sqrt((1 - rho²) / (N c)) (c columns),
    three times over and propagated through alpha^(1/3), bounds how far the bandwidth may be
    from the closed form with the true rho (0.4 to 2.8 lags here), one more lag for the
    floor."""
    samples, columns = 20000, 4
    alpha = 4 * rho**2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    exact = 1.1447 * (alpha * samples) ** (1 / 3)
    se = np.sqrt((1 - rho**2) / (samples * columns))
    dlog_alpha = 2 / rho + 2 / (1 - rho) - 2 / (1 + rho)
    spread = 3 * se * dlog_alpha * exact / 3
    got = hac_bandwidth(ar1(rho, samples, columns, 1))
    assert abs(got - exact) <= spread + 1, (got, exact)  # + 1: the floor


def test_white_scores_need_no_lags() -> None:
    """White scores: alpha is the squared sample autocorrelation, of order 1/N, so the
    bandwidth 1.1447 (alpha N)^(1/3) is of order one: at most 2 lags."""
    assert hac_bandwidth(ar1(0.0, 20000, 4, 2)) <= 2


def test_the_sandwich_is_statsmodels_hac_ols_covariance() -> None:
    """``_covariance`` on a linear regression (the Jacobian is the design matrix, the residuals
    the OLS residuals) is statsmodels' HAC covariance of the OLS estimate with the same lags and
    its small-sample factor N / (N - d): the same estimator by another implementation, to the
    round-off of two least-squares solutions (1e-9 relative: the design's condition number is
    below 10)."""
    rng = np.random.default_rng(3)
    samples = 3000
    X = np.column_stack([np.ones(samples), rng.standard_normal((samples, 2))])
    y = X @ np.array([1.0, -2.0, 0.5]) + ar1(0.7, samples, 1, 4)[:, 0]
    fit = OLS(y, X).fit()
    cov, rank, lags, _ = _covariance(X, fit.resid, 1)
    assert rank == 3 and lags > 0
    theirs = fit.get_robustcov_results(cov_type="HAC", maxlags=lags, use_correction=True)
    np.testing.assert_allclose(cov, theirs.cov_params(), rtol=1e-9)
