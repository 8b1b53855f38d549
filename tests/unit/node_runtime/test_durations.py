"""Durations: the run's percentiles over every value kept, a report's over its window only
(numpy's percentiles of the same values are the reference)."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.durations import Durations


def expected(values: np.ndarray) -> dict[str, float]:
    ms = 1e3 * values
    return {"p50": np.percentile(ms, 50), "p99": np.percentile(ms, 99), "max": ms.max()}


def test_summary_and_recent_windows_wrap_around_the_ring() -> None:
    rng = np.random.default_rng(7)
    values = rng.exponential(1e-4, 250)
    durations = Durations(keep=100)
    for v in values[:30]:
        durations.add(v)
    assert durations.recent() == pytest.approx(expected(values[:30]), rel=1e-12)
    for v in values[30:170]:             # 140 more: past the end of the ring
        durations.add(v)
    # the window since the last report: only the last 100 are kept
    assert durations.recent() == pytest.approx(expected(values[70:170]), rel=1e-12)
    for v in values[170:250]:            # a window that wraps around the ring's end
        durations.add(v)
    assert durations.recent() == pytest.approx(expected(values[170:250]), rel=1e-12)
    assert durations.summary() == pytest.approx(expected(values[150:250]), rel=1e-12)


def test_an_empty_window_reports_nan() -> None:
    durations = Durations(keep=10)
    assert all(np.isnan(v) for v in durations.summary().values())
    durations.add(1e-3)
    durations.recent()
    assert all(np.isnan(v) for v in durations.recent().values())


@pytest.mark.parametrize("n", [1, 2, 3, 99, 100, 101, 1000])
def test_every_window_length_gives_numpys_linear_percentiles(n: int) -> None:
    # the rank (n - 1) q falls on an order statistic, between two, or on the last one
    values = np.random.default_rng(n).exponential(1e-4, n)
    durations = Durations(keep=2000)
    for v in values:
        durations.add(v)
    assert durations.recent() == pytest.approx(expected(values), rel=1e-12)
