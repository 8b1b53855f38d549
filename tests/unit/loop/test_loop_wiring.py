"""What every loop process agrees on for a scene (stillframe.loop.wiring), against the topic
contract (docs/nodes.md): the estimator's inputs and the command topic."""

from __future__ import annotations

import pytest

from stillframe.contract import topics
from stillframe.loop.wiring import command_topic, estimator_inputs
from tests.support.scenes import thesis_scene

SENSORS = (*topics.FLOOR_IMU, topics.PENDULUM_JOINT_STATES, topics.EXCITATION_WRENCH)
OPEN_LOOP = ["estimator.type=none", "controller.type=none"]


@pytest.mark.parametrize(("scene", "overrides", "inputs", "command"), [
    ("thesis_lqg", [], SENSORS, topics.TORQUE_CMD),
    ("thesis_euk_ekf", [], (*SENSORS, topics.FLOOR3_LOAD_CELL), topics.FORCE_CMD),
    ("thesis_euk_pendulum", [], (*SENSORS, topics.STATE_TRUTH), topics.TORQUE_CMD),
    ("thesis_euk_floor", [], (*SENSORS, topics.FLOOR3_LOAD_CELL, topics.STATE_TRUTH),
     topics.FORCE_CMD),
    ("thesis_lqg", OPEN_LOOP, (), None),
])
def test_inputs_and_command_topic_follow_the_scene(scene: str, overrides: list[str],
                                                   inputs: tuple, command: object) -> None:
    s = thesis_scene(scene, overrides)
    assert estimator_inputs(s) == inputs
    assert command_topic(s) == command
