"""RSS growth after warm-up (stillframe.app.bench.rss), against numbers worked by hand."""

from __future__ import annotations

import os

import numpy as np
import pytest

from stillframe.app.bench.rss import RssLog, history_bytes, rss_bytes

MIB = 2**20


def test_history_bytes_is_one_row_per_sample_and_one_per_integrator_step() -> None:
    # 32 Hz, 32 steps per sample, 1 s: 32 · (12 + 32 · 7) float64
    assert history_bytes(1.0, 1 / 32, 32) == 8 * 32 * (12 + 32 * 7)


def test_growth_from_the_first_sample_after_warmup_to_the_last() -> None:
    log = RssLog()
    for t, rss in [(0.0, 50 * MIB), (10.0, 200 * MIB), (50.0, 204 * MIB), (100.0, 202 * MIB)]:
        log.add("node", t, rss)
    g = log.growth("node", warmup_s=10.0)
    assert (g["warm_mib"], g["end_mib"], g["peak_mib"]) == (200.0, 202.0, 204.0)
    assert g["growth_pct"] == pytest.approx(1.0) and g["samples"] == 3
    assert log.growth("node", warmup_s=60.0) == {}        # one sample after warm-up: no figure
    assert log.growth("node", 10.0, until_s=100.0)["growth_pct"] == pytest.approx(2.0)


def test_simulator_growth_net_of_its_histories() -> None:
    period, substeps = 1 / 32, 32
    log = RssLog()
    stored = history_bytes(100.0, period, substeps) - history_bytes(10.0, period, substeps)
    log.add("sim_node", 10.0, 200 * MIB)
    log.add("sim_node", 100.0, 200 * MIB + stored + 2 * MIB)   # histories + 2 MiB more
    g = log.growth("sim_node", 10.0, (period, substeps))
    assert g["history_mib"] == pytest.approx(stored / MIB)
    assert g["net_growth_pct"] == pytest.approx(1.0)


def test_rss_follows_memory_touched_and_is_none_for_no_process() -> None:
    before = rss_bytes(os.getpid())
    block = np.ones(64 * MIB // 8)                       # 64 MiB, every page touched
    after = rss_bytes(os.getpid())
    assert after - before == pytest.approx(64 * MIB, abs=8 * MIB)
    assert block.sum() == 8 * MIB
    assert rss_bytes(2**30) is None
