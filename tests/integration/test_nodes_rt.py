"""The real-time mode changes when the nodes run, not what they compute: the three nodes with
every practice (``rt: all``) in lock-step give the one-process loop's numbers to the last bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stillframe.loop.closed_loop import run_closed_loop
from tests.support.nodes import SHORT_LQG, run_loop
from tests.support.scenes import thesis_scene


def test_rt_all_in_lockstep_equals_one_process(ros_domain: int, tmp_path: Path) -> None:
    result, hist = run_loop(tmp_path, "thesis_lqg", SHORT_LQG, rt="all")
    reference = run_closed_loop(thesis_scene("thesis_lqg", SHORT_LQG))
    assert result["reduction_pct"] == reference.evaluation["reduction_pct"]
    assert result["complete"] is True
    np.testing.assert_array_equal(hist["truth"], reference.truth)
    np.testing.assert_array_equal(hist["command"], reference.command)
    assert np.count_nonzero(hist["command"]) > 0
