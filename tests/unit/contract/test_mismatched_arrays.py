"""JointState arrays of mismatched lengths (issue 11, item 5): the codecs read what is there and
NaN for what is not, never an IndexError (a hostile writer cannot crash a node with them)."""

from __future__ import annotations

import math

import numpy as np

from stillframe.contract import messages
from stillframe.contract.codecs import (
    ENCODER_CHANNEL,
    applied_torque,
    physical_state,
    sensor_reading,
)


def _joint_state(names: list[str], position: list[float], velocity: list[float],
                 effort: list[float]) -> object:
    return messages.new("sensor_msgs/msg/JointState", name=names,
                        position=np.array(position, dtype=float),
                        velocity=np.array(velocity, dtype=float),
                        effort=np.array(effort, dtype=float))


def test_encoder_reads_what_is_there_and_nan_for_the_rest() -> None:
    assert sensor_reading(ENCODER_CHANNEL, _joint_state(["pendulum", "x"], [0.3], [], [])) == 0.3
    short = _joint_state(["x", "pendulum"], [0.3], [], [1.0])     # its index 1 is missing
    assert math.isnan(sensor_reading(ENCODER_CHANNEL, short))
    assert math.isnan(applied_torque(short))
    assert applied_torque(_joint_state([], [], [], [2.0, 3.0])) == 2.0   # unnamed: index 0
    assert math.isnan(sensor_reading(ENCODER_CHANNEL, _joint_state([], [], [], [])))


def test_state_reads_each_name_where_its_value_exists() -> None:
    names = ["x1", "x2", "x3", "phi"]
    msg = _joint_state(names, [1.0, 2.0], [5.0, 6.0, 7.0, 8.0, 9.0], [])
    got = physical_state(msg)
    np.testing.assert_array_equal(got[[0, 1, 4, 5, 6, 7]], [1.0, 2.0, 5.0, 6.0, 7.0, 8.0])
    assert np.isnan(got[[2, 3]]).all()
