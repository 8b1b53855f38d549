"""Soak (issue 11, item 7): one hour of simulated lock-step LQG through the three node processes
(115,200 samples at 32 Hz); each process's RSS after warm-up (10 % of the run) grows less than
5 % (the simulator's net of the histories it keeps by design), and the loop's counters show no
anomaly. ``stillframe bench soak --json`` runs the same and prints the figures."""

from __future__ import annotations

from pathlib import Path

import pytest

from stillframe.app.bench.soak import GROWTH_LIMIT_PCT, soak


@pytest.mark.long
def test_one_hour_of_lockstep_lqg_keeps_memory_and_counters(ros_domain: int,
                                                            tmp_path: Path) -> None:
    report = soak(3600.0, 0.1, 5.0, tmp_path)
    assert report["steps"] == 115_200
    for name in ("sim_node", "estimator_node", "controller_node"):
        g = report["rss"][name]
        assert g.get("net_growth_pct", g["growth_pct"]) < GROWTH_LIMIT_PCT, (name, g)
    counters = report["counters"]
    assert counters["safe_state_samples"] == 0 and counters["rejected_commands"] == 0
    assert counters["malformed_samples"] == 0
    assert counters["complete"] is True
