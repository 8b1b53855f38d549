"""The frame pHDAE as the plant of the closed loop: in one process and through the three node
processes over DDS (lock-step: the same numbers to the last bit)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stillframe.loop.closed_loop import run_closed_loop
from tests.support.nodes import run_loop
from tests.support.scenes import thesis_scene

SHORT = ["duration=2.0", "controller.start=1.0", "evaluation.window=1.0"]
FREE = ["excitation.type=none", "initial.floors=[0.002, 0.004, 0.005]", "initial.phi=0.2",
        "controller.start=0.5", "duration=1.5", "evaluation.window=0.5"]


def late_phi_rate_rms(overrides: list[str]) -> float:
    history = run_closed_loop(thesis_scene("ph_passivity", FREE + overrides))
    late = history.t > 1.0
    return float(np.sqrt(np.mean(history.truth[late, 7] ** 2)))


@pytest.mark.slow
def test_passivity_law_damps_the_ph_plant_free_swing():
    controlled = late_phi_rate_rms([])
    uncontrolled = late_phi_rate_rms(["controller.type=none", "estimator.type=none"])
    assert controlled < 0.8 * uncontrolled


@pytest.mark.slow
def test_three_processes_on_the_ph_plant_equal_one_process(ros_domain: int,
                                                           tmp_path: Path) -> None:
    result, hist = run_loop(tmp_path, "ph_passivity", SHORT)
    reference = run_closed_loop(thesis_scene("ph_passivity", SHORT))
    assert result["reduction_pct"] == reference.evaluation["reduction_pct"]
    assert result["plant"]["model"] == "ph2"
    np.testing.assert_array_equal(hist["truth"], reference.truth)
    np.testing.assert_array_equal(hist["command"], reference.command)
