"""The simulator's decimated taps (issue 27 must show 5: the tracker reads thinned data, so it
costs the loop's writers no send per sample). References: scipy's ``upfirdn`` (a second
implementation of filtering and keeping every q-th sample), the filter's response by
``scipy.signal.freqz``, and closed-form sinusoids: one inside the band comes through with its
amplitude and phase at the tap's stamps, one that decimation without a filter would fold onto
the band is gone."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from stillframe.app.tracking import tracker_command
from stillframe.config.scene import load_scene
from stillframe.locations import SCENES_DIR
from stillframe.loop.decimated_taps import (
    PASS_EDGE,
    STOP_EDGE,
    Decimator,
    anti_alias_taps,
    decimated_topic,
    decimation_factor,
    undecimated,
)

RATE_HZ = 1000.0
PERIOD_NS = 1_000_000


def stream(decimator: Decimator, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Push every row of ``x`` (sample k stamped k ms): the tapped values and their stamps."""
    values, stamps = [], []
    for k, row in enumerate(x):
        out = decimator.push(row, k * PERIOD_NS)
        if out is not None:
            values.append(out[0])
            stamps.append(out[1])
    return np.array(values), np.array(stamps)


def test_the_factor_keeps_the_tap_at_50_hz_or_more() -> None:
    assert [decimation_factor(r) for r in (32.0, 64.0, 99.0, 100.0, 250.0, 1000.0)] == \
        [1, 1, 1, 2, 5, 20]
    assert undecimated(decimated_topic("/frame/floor1/imu")) == "/frame/floor1/imu"
    assert undecimated("/frame/floor1/imu") == "/frame/floor1/imu"


@pytest.mark.parametrize("factor", [2, 20])
def test_the_filter_is_flat_in_the_band_and_60_db_down_where_it_would_fold(factor: int) -> None:
    h = anti_alias_taps(factor)
    assert len(h) % 2 == 1 and ((len(h) - 1) // 2) % factor == 0
    np.testing.assert_allclose(h, h[::-1])                       # linear phase
    out_rate = RATE_HZ / factor
    f, response = signal.freqz(h, worN=1 << 15, fs=RATE_HZ)
    gain_db = 20 * np.log10(np.abs(response))
    assert np.abs(gain_db[f <= PASS_EDGE * out_rate]).max() < 0.02
    assert gain_db[f >= STOP_EDGE * out_rate].max() < -58.0


def test_streaming_equals_scipys_upfirdn_and_stamps_the_filters_centre() -> None:
    x = np.random.default_rng(3).standard_normal((4000, 3))
    decimator = Decimator(20, 3)
    values, stamps = stream(decimator, x)
    h, delay = decimator.taps, decimator.delay
    ref = np.stack([signal.upfirdn(h, x[:, c], up=1, down=20) for c in range(3)], axis=1)
    # output j of upfirdn ends at input j·q; the tap's value for centre c ends at c + delay
    ends = stamps // PERIOD_NS + delay
    assert np.all(stamps // PERIOD_NS % 20 == 0) and stamps[0] == 0
    np.testing.assert_allclose(values, ref[ends // 20], rtol=0, atol=1e-12)
    assert len(values) == (len(x) - 1 - delay) // 20 + 1


def test_a_mode_in_the_band_comes_through_and_what_would_fold_onto_it_does_not() -> None:
    t = np.arange(20_000) / RATE_HZ
    low, folding = 5.0, 40.0        # 40 Hz would read as 10 Hz at 50 Hz without the filter
    x = np.column_stack([np.sin(2 * np.pi * low * t + 0.3), np.sin(2 * np.pi * folding * t)])
    values, stamps = stream(Decimator(decimation_factor(RATE_HZ), 2), x)
    ts = stamps * 1e-9
    inner = slice(10, None)     # past the filter's start, which sees zeros before the first sample
    np.testing.assert_allclose(values[inner, 0], np.sin(2 * np.pi * low * ts[inner] + 0.3),
                               rtol=0, atol=2e-3)
    assert np.abs(values[inner, 1]).max() < 10 ** (-58 / 20)
    naive = x[::20, 1]          # thinning alone: a full-size 10 Hz sinusoid
    assert np.abs(naive).max() > 0.9


def test_the_launch_tracker_reads_the_taps_at_their_rate_at_1_khz() -> None:
    scene = load_scene(SCENES_DIR / "thesis_lqg.yaml", ["sensors.rate_hz=1000",
                                                         "integrator.dt=0.001"])
    argv = tracker_command(scene, SCENES_DIR / "unused.jsonl", lockstep=False)
    params = dict(a.split(":=", 1) for a in argv if ":=" in a)
    assert params["rate_hz"] == "50.0" and params["idle"] == "true"
    assert params["inputs"] == '["/_decimated/frame/excitation/wrench"]'
    assert params["outputs"].startswith('["/_decimated/frame/floor1/imu"')
    at_32 = dict(a.split(":=", 1) for a in tracker_command(
        load_scene(SCENES_DIR / "thesis_lqg.yaml"), SCENES_DIR / "unused.jsonl",
        lockstep=True) if ":=" in a)
    assert at_32["rate_hz"] == "32.0" and at_32["reliable"] == "true"
    assert at_32["inputs"] == '["/frame/excitation/wrench"]'
