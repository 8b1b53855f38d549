"""The CUSUM of :mod:`stillframe.identification.change_detection` against its closed form: after
the reference, a step of s reference standard deviations adds s − ν per update to the mode's
upper statistic, so the alarm comes at the first update n with n (s − ν) > h, and the onset is
the step's first update."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.errors import InputError
from stillframe.identification.change_detection import ChangeDetector, CusumSettings


def test_a_step_is_declared_when_the_closed_form_says_and_its_onset_is_the_step() -> None:
    reference = np.array([[1.0, 5.0], [1.002, 5.001], [0.998, 4.999], [1.0, 5.0]])
    settings = CusumSettings(reference_updates=4, drift=2.0, threshold=40.0,
                             min_relative_std=1e-6)
    detector = ChangeDetector(settings)
    for i, f in enumerate(reference):
        assert detector.update(float(i), f) is None
    std = reference.std(axis=0, ddof=1)
    np.testing.assert_allclose(detector.std, std, rtol=1e-12)
    shift = 7.0                                    # reference stds, on mode 2 only
    stepped = reference.mean(axis=0) + np.array([0.0, shift * std[1]])
    expected = int(np.floor(settings.threshold / (shift - settings.drift))) + 1   # 9
    for n in range(1, expected + 1):
        found = detector.update(10.0 + n, stepped)
        if n < expected:
            assert found is None
            assert detector.upper[1] == pytest.approx(n * (shift - settings.drift), rel=1e-12)
            assert detector.upper[0] == detector.lower[0] == 0.0
    assert found is not None
    assert (found.mode, found.t, found.onset_t) == (1, 10.0 + expected, 11.0)
    assert found.statistic == pytest.approx(expected * (shift - settings.drift), rel=1e-12)


def test_the_spread_has_a_floor_and_unmatched_updates_are_skipped() -> None:
    detector = ChangeDetector(CusumSettings(reference_updates=2, min_relative_std=1e-3))
    detector.update(0.0, [2.0, 4.0])
    detector.update(1.0, [2.0, 4.0])               # no spread at all: the floor
    np.testing.assert_allclose(detector.std, [2e-3, 4e-3])
    assert detector.update(2.0, [2.0]) is None     # a mode missing: skipped, counted
    assert detector.update(3.0, [2.0, 4.0, 6.0]) is None
    assert detector.skipped == 2
    assert not detector.upper.any()
    detector.restart()
    assert not detector.watching


def test_settings_that_cannot_detect_are_refused() -> None:
    with pytest.raises(InputError, match="reference_updates"):
        ChangeDetector(CusumSettings(reference_updates=1))
    with pytest.raises(InputError, match="threshold > 0"):
        ChangeDetector(CusumSettings(threshold=0.0))
