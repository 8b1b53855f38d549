"""The estimate's RMS error against the truth, by stamp, against numpy on the same arrays."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from stillframe.app.bench.estimate_error import EstimateLog
from stillframe.contract.codecs import STATE_NAMES

PERIOD_NS = 10_000_000


def joint_state(stamp_ns: int, state: np.ndarray, names: list[str] = STATE_NAMES) -> object:
    """A JointState-shaped message (names in the given order)."""
    order = [STATE_NAMES.index(n) for n in names]
    return SimpleNamespace(
        header=SimpleNamespace(stamp=SimpleNamespace(sec=stamp_ns // 1_000_000_000,
                                                     nanosec=stamp_ns % 1_000_000_000)),
        name=list(names), position=[state[i] for i in order],
        velocity=[state[4 + i] for i in order])


def test_rms_error_over_the_samples_both_have() -> None:
    rng = np.random.default_rng(3)
    truth = rng.normal(size=(50, 8))
    estimate = truth + rng.normal(scale=0.1, size=truth.shape)
    log = EstimateLog(PERIOD_NS)
    # every third sample missing; names in another order; a NaN estimate; a duplicate stamp
    for k in range(50):
        if k % 3:
            log.on_estimate(joint_state(k * PERIOD_NS, estimate[k], STATE_NAMES[::-1]))
    log.on_estimate(joint_state(4 * PERIOD_NS, estimate[4] + 1.0))   # the first one counts
    log.estimates[5] = np.full(8, np.nan)
    result = log.rms_error(truth, from_k=10)
    used = [k for k in range(10, 50) if k % 3 and k != 5]
    error = estimate[used] - truth[used]
    assert result["samples"] == len(used)
    assert result["missing"] == sum(1 for k in range(10, 50) if k % 3 == 0)
    np.testing.assert_allclose(result["rms"], np.sqrt((error ** 2).mean(axis=0)), rtol=1e-12)
    np.testing.assert_allclose(result["rms_floors_m"], np.sqrt((error[:, :3] ** 2).mean()),
                               rtol=1e-12)
    np.testing.assert_allclose(result["relative_floors"], np.sqrt((error[:, :3] ** 2).mean())
                               / np.sqrt((truth[used, :3] ** 2).mean()), rtol=1e-12)
    assert result["rms_phi_rad"] == result["rms"][3]


def test_no_estimate_gives_nan_not_an_error() -> None:
    result = EstimateLog(PERIOD_NS).rms_error(np.zeros((4, 8)))
    assert result["samples"] == 0 and result["missing"] == 4
    assert np.isnan(result["rms_floors_m"])
