"""``stillframe launch`` leaves discovery as the environment says, like ``ros2 launch``: SUBNET
when ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is unset (rcl's default), the environment the children
inherit unchanged; a range that is set is taken, a wrong one refused."""

from __future__ import annotations

import os

import pytest

from stillframe.app.launcher import launch_discovery
from stillframe.errors import InputError


def test_unset_means_subnet_and_the_environment_is_left_alone(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ROS_AUTOMATIC_DISCOVERY_RANGE", raising=False)
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    assert launch_discovery() == "SUBNET"
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE" not in os.environ


@pytest.mark.parametrize("value", ["LOCALHOST", "SUBNET", "OFF", "SYSTEM_DEFAULT"])
def test_a_range_that_is_set_is_taken(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", value)
    assert launch_discovery() == value and os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == value


def test_a_wrong_range_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LAN")
    with pytest.raises(InputError, match="ROS_AUTOMATIC_DISCOVERY_RANGE='LAN': expected one of"):
        launch_discovery()
