"""``stillframe bench transport`` reports consistent figures (not a speed assertion)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.support.middleware import run_stillframe


@pytest.mark.slow
def test_bench_transport_json_is_consistent(ros_domain: int) -> None:
    result = run_stillframe("bench", "transport", "--duration", "1", "--rate", "200", "--json",
                            timeout=180)
    assert result.returncode == 0, result.stderr
    doc = json.loads(result.stdout)
    assert doc["backends"] == ["dds", "rclpy"]  # rclpy is installed by `make setup`
    for variant in ("raw", "typed", "dds_raw", "dds", "rclpy"):
        r = doc[variant]
        # 1 s at 200 Hz: at most 200 pings are due (one more at the boundary); a loaded
        # machine that falls behind sends the late ones back to back, and fewer if it cannot
        # catch up before the second is over
        assert 0 < r["sent"] <= 201
        assert r["received"] + r["lost"] == r["sent"]
        assert r["received"] > 0.5 * r["sent"]
        assert 0 < r["p50_us"] <= r["p99_us"] <= r["max_us"]
    for key in ("p50_us", "p99_us"):
        for variant in ("dds_raw", "dds", "rclpy"):
            assert np.isclose(doc["api_over_raw"][variant][key],
                              doc[variant][key] / doc["raw"][key])
        assert np.isclose(doc["rclpy_over_dds"][key], doc["rclpy"][key] / doc["dds"][key])
