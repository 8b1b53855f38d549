"""Prediction-error refinement (:mod:`stillframe.identification.pem`): exact on noise-free data,
and its
95 % intervals against the Monte Carlo spread of the estimates on a known system."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.identification.pem import refine_prediction_error
from stillframe.identification.pipeline import identify
from stillframe.identification.sweep import shear_building, simulate


def test_refinement_recovers_a_noise_free_system_to_round_off() -> None:
    """Start from the OKID/ERA model of a 30 dB record (frequencies off by ~0.2 %), refine on
    the noise-free record of the same input: the five modes come back to ~1e-12 (the true ones
    are the building's eigenvalues, independent of identification)."""
    building = shear_building(2)
    noisy = simulate(building, 1024, 30.0, 0)
    clean = simulate(building, 1024, 400.0, 0)
    start = identify(noisy.u, noisy.y, noisy.dt, "okid-eradc", 10)
    assert np.max(np.abs(start.modes.frequency_hz / building.frequency_hz - 1)) > 1e-4
    ref = refine_prediction_error(start.A, start.B, start.C, start.D, start.G, clean.u, clean.y,
                                  clean.dt)
    assert ref.modes.frequency_hz == pytest.approx(building.frequency_hz, rel=1e-10)
    assert ref.modes.damping_ratio == pytest.approx(building.damping_ratio, rel=1e-9)
    assert np.max(ref.frequency_ci_hz[:, 1] - ref.frequency_ci_hz[:, 0]) < 1e-9


@pytest.mark.slow
def test_intervals_agree_with_the_monte_carlo_spread() -> None:
    """A 2-mode building, 1024 samples at 20 dB, 30 noise and input realisations: the standard
    deviation the refinement predicts (mean over runs) is within a factor 1.75 of the spread of
    the estimates, and the 95 % intervals cover the true values in >= 80 % of the 120 mode
    figures (the sampling error of 30 runs at 95 % is about 4 %). Measured: predicted / Monte
    Carlo standard deviation 0.65 and 1.02 (frequencies), 0.86 and 1.04 (damping ratios);
    coverage 87.5 %. The first mode's frequency interval is too narrow by about a third."""
    building = shear_building(14)
    freq, damp, f_std, z_std, covered = [], [], [], [], []
    for seed in range(30):
        rec = simulate(building, 1024, 20.0, 100 + seed)
        ident = identify(rec.u, rec.y, rec.dt, "okid-eradc", 4, refine=True)
        ref = ident.refinement
        freq.append(ref.modes.frequency_hz)
        damp.append(ref.modes.damping_ratio)
        f_std.append(ref.frequency_std_hz)
        z_std.append(ref.damping_std)
        covered.append(np.concatenate([
            (ref.frequency_ci_hz[:, 0] <= building.frequency_hz)
            & (building.frequency_hz <= ref.frequency_ci_hz[:, 1]),
            (ref.damping_ci[:, 0] <= building.damping_ratio)
            & (building.damping_ratio <= ref.damping_ci[:, 1])]))
    for estimates, predicted in ((freq, f_std), (damp, z_std)):
        ratio = np.mean(predicted, axis=0) / np.std(estimates, axis=0, ddof=1)
        assert np.all((ratio > 1 / 1.75) & (ratio < 1.75)), ratio
    assert np.mean(covered) >= 0.8
