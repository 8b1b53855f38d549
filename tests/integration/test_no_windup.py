"""No windup (issue 11, item 6): the thesis LQG against the nonlinear lumped plant with only the
actuator limited (``actuators.torque_limit=2``, controller unlimited).

Before: the estimator was fed the command, not the torque the saturated motor applied, and the
command ran away to 1e187 with no warning. Now the estimator gets the applied torque (the
simulator's encoder ``effort``), the controller never commands beyond the actuator's limit and
flags a law output beyond ten times it (``runaway``), and the three processes in lock-step still
give the one-process loop's numbers to the last bit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stillframe.loop.closed_loop import open_loop_truth, run_closed_loop
from tests.support.nodes import run_loop
from tests.support.scenes import thesis_scene

LIMIT = 2.0
ACTUATOR_ONLY = ["plant.model=scene", f"actuators.torque_limit={LIMIT}", "duration=8",
                 "controller.start=4", "evaluation.window=2"]


def test_actuator_limit_only_lqg_stays_bounded_and_is_flagged() -> None:
    scene = thesis_scene("thesis_lqg", ACTUATOR_ONLY)
    history = run_closed_loop(scene)
    assert np.all(np.isfinite(history.truth)) and np.all(np.isfinite(history.fine_floors))
    torque = history.command[:, 0]
    assert np.all(np.isfinite(torque)) and np.max(np.abs(torque)) == LIMIT
    counters = history.evaluation["controller"]
    assert counters["saturated"] > 0 and counters["runaway"] > 0   # flagged, not silent
    # the floors stay within a few times the uncontrolled motion of the same run (same seeds)
    _t, floors, _v = open_loop_truth(scene)
    assert np.max(np.abs(history.fine_floors)) < 3 * np.max(np.abs(floors))


def test_actuator_limit_only_lockstep_equals_one_process(ros_domain: int,
                                                         tmp_path: Path) -> None:
    result, hist = run_loop(tmp_path, "thesis_lqg", ACTUATOR_ONLY)
    reference = run_closed_loop(thesis_scene("thesis_lqg", ACTUATOR_ONLY))
    assert result["complete"] is True
    np.testing.assert_array_equal(hist["truth"], reference.truth)
    np.testing.assert_array_equal(hist["command"], reference.command)
    assert result["peak_command"] == reference.evaluation["peak_command"] == LIMIT
