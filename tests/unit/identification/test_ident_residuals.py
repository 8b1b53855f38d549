"""Residual checks of the refined model (:mod:`stillframe.identification.residual_tests`): the
portmanteau test and the independence test against their χ² distributions, the SNR read off the
errors, and the warning they give where a mode is missed without any other check firing."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from stillframe.identification.pipeline import identify
from stillframe.identification.residual_tests import (
    LOW_SNR_DB,
    WHITENESS_LEVEL,
    chi2_tail,
    independence,
    residual_warnings,
    snr_db,
    whiteness,
)
from stillframe.identification.sweep import score, shear_building, simulate


def test_the_chi2_tail_is_scipy_stats_own() -> None:
    """The tail the tests take their p-values from is scipy.stats.chi2.sf's, value for value,
    over statistics from 0 to far in the tail and the degrees of freedom the tests use."""
    from scipy import stats

    statistic = np.concatenate([[0.0], np.geomspace(1e-3, 2e3, 200)])
    for dof in (1, 3, 25, 75, 300):
        np.testing.assert_array_equal(chi2_tail(statistic, dof), stats.chi2.sf(statistic, dof))


def test_whiteness_rejects_white_noise_at_its_level() -> None:
    """400 records of white Gaussian noise (3 outputs, 512 samples): the Bonferroni-corrected
    test rejects in at most its level (1 %) plus three binomial standard deviations."""
    rng = np.random.default_rng(0)
    rejected = sum(not whiteness(rng.standard_normal((512, 3))).white for _ in range(400))
    sd = np.sqrt(400 * WHITENESS_LEVEL * (1 - WHITENESS_LEVEL))
    assert rejected <= 400 * WHITENESS_LEVEL + 3 * sd


def test_whiteness_statistic_is_box_pierce() -> None:
    """The statistic against a direct sum of the sample autocorrelations (numpy.correlate)."""
    rng = np.random.default_rng(1)
    e = rng.standard_normal((300, 1))
    x = e[:, 0] - e[:, 0].mean()
    full = np.correlate(x, x, mode="full")[x.size - 1:]
    expected = x.size * np.sum((full[1:11] / full[0]) ** 2)
    assert whiteness(e, lags=10).statistic[0] == pytest.approx(expected, rel=1e-12)


def test_whiteness_detects_a_narrow_band_component() -> None:
    """White noise plus a lightly damped resonance (ζ = 1 %) driven by noise 10 dB weaker: the
    errors are coloured and the test says so."""
    rng = np.random.default_rng(2)
    pole = 0.99 * np.exp(1j * 2 * np.pi * 0.05)
    ringing = signal.lfilter([1.0], np.poly([pole, pole.conjugate()]).real,
                             rng.standard_normal(1024))
    ringing *= 10 ** (-10 / 20) / ringing.std()
    assert not whiteness((rng.standard_normal(1024) + ringing)[:, None]).white


def test_independence_rejects_independent_errors_at_its_level() -> None:
    """400 records of white errors (3 outputs) and independent coloured inputs (2, 512 samples):
    the Bonferroni-corrected test rejects in at most its level (1 %) plus three binomial
    standard deviations."""
    rng = np.random.default_rng(4)
    rejected = 0
    for _ in range(400):
        u = signal.lfilter([1.0], [1.0, -0.8], rng.standard_normal((512, 2)), axis=0)
        rejected += not independence(rng.standard_normal((512, 3)), u).independent
    sd = np.sqrt(400 * WHITENESS_LEVEL * (1 - WHITENESS_LEVEL))
    assert rejected <= 400 * WHITENESS_LEVEL + 3 * sd


def test_independence_statistic_is_the_regression_on_the_past_inputs() -> None:
    """The statistic against a second computation: N times the share of the (centred) errors'
    sum of squares that a least-squares fit on the inputs lagged 1..M explains (numpy.lstsq on
    the lagged matrix built column by column)."""
    rng = np.random.default_rng(5)
    u = rng.standard_normal((400, 2))
    e = rng.standard_normal((400, 1)) + 0.1 * np.roll(u[:, :1], 3, axis=0)
    lags = 7
    uc, ec = u - u.mean(axis=0), e[:, 0] - e[:, 0].mean()
    phi = np.column_stack([uc[lags - k:400 - k, j] for k in range(1, lags + 1) for j in range(2)])
    target = ec[lags:]
    fit = phi @ np.linalg.lstsq(phi, target, rcond=None)[0]
    expected = target.size * (fit @ fit) / (target @ target)
    assert independence(e, u, lags=lags).statistic[0] == pytest.approx(expected, rel=1e-10)


def test_independence_finds_a_missing_input_path_that_whiteness_does_not() -> None:
    """Errors that are white but carry the input through a short filter (a model whose
    input-to-output part lacks a mode leaves such errors): white by the portmanteau test,
    rejected by the independence test."""
    rng = np.random.default_rng(6)
    u = rng.standard_normal((2048, 1))
    leak = signal.lfilter([0.0, 0.3, -0.2], [1.0], u[:, 0])
    e = (rng.standard_normal(2048) + leak)[:, None]
    assert whiteness(e).white
    assert not independence(e, u).independent
    assert any("correlated with the past inputs" in w for w in residual_warnings(e + 1, e, u))


def test_snr_from_the_errors() -> None:
    """An output of known signal and noise variances: the SNR is theirs (to sampling error)."""
    rng = np.random.default_rng(3)
    noise = 0.1 * rng.standard_normal((20000, 2))
    y = np.sin(np.linspace(0, 400, 20000))[:, None] * np.array([1.0, 0.5]) + noise
    expected = 10 * np.log10(np.array([0.5, 0.125]) / 0.01)
    assert snr_db(y, noise) == pytest.approx(expected, abs=0.1)


def test_missed_low_mode_is_not_silent() -> None:
    """The issue's silent case: a 5-storey building at 20 dB with 256 samples, whose 1.46 Hz mode
    spans 6.7 cycles and lies below the noise. The refined model misses it and, before the
    residual test, gave no warning; the errors' whiteness test now warns."""
    building = shear_building(0)
    rec = simulate(building, 256, 20.0, 0)
    ident = identify(rec.u, rec.y, rec.dt, "okid-eradc", "auto", refine=True)
    result = score(ident.modes.frequency_hz, ident.modes.damping_ratio, building.frequency_hz,
                   building.damping_ratio)
    assert result["missed"] == 1
    assert any(w.startswith("prediction errors are not white") for w in ident.warnings)


def test_correct_model_passes_the_residual_checks() -> None:
    """40 dB, 1024 samples of a 3-mode building: all modes within 0.1 %, and neither the
    whiteness test nor the SNR check fires (they do not warn on everything)."""
    building = shear_building(1)
    rec = simulate(building, 1024, 40.0, 1)
    ident = identify(rec.u, rec.y, rec.dt, "okid-eradc", "auto", refine=True)
    result = score(ident.modes.frequency_hz, ident.modes.damping_ratio, building.frequency_hz,
                   building.damping_ratio)
    assert result["frequency_error"] < 1e-3
    assert whiteness(ident.refinement.errors).white
    assert np.max(snr_db(rec.y, ident.refinement.errors)) > 35
    assert residual_warnings(rec.y, ident.refinement.errors) == []


def test_low_snr_record_says_modes_may_be_hidden() -> None:
    """The same building at 8 dB: the SNR read off the refined model's errors is within 1.5 dB
    of the simulated one, below the limit, and identify says so."""
    building = shear_building(1)
    rec = simulate(building, 1024, 8.0, 1)
    ident = identify(rec.u, rec.y, rec.dt, "okid-eradc", "auto", refine=True)
    best = np.max(snr_db(rec.y, ident.refinement.errors))
    assert abs(best - 8.0) < 1.5 and best < LOW_SNR_DB
    assert any(w.startswith("low signal-to-noise ratio") for w in ident.warnings)
