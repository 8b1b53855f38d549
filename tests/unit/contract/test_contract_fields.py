"""The topic contract's ``field`` column is the one statement of which message field carries
which quantity: the codecs write exactly there, and bag channels read there by default."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest

from stillframe.bags.channels import DEFAULT_FIELDS, _default_field
from stillframe.config.loop_sections import Sensors
from stillframe.contract import codecs, topics
from stillframe.contract.signals import Command, Sample


def at(msg: Any, path: str) -> float:
    """The value at a dotted path with [i] indices, read independently of the codecs."""
    value = msg
    for name, index in re.findall(r"([A-Za-z_]\w*)(?:\[(\d+)\])?", path):
        value = getattr(value, name)
        if index:
            value = value[int(index)]
    return float(value)


def test_the_sensor_codec_writes_each_quantity_into_the_contracts_field() -> None:
    sample = Sample(t=0.5, measurements=np.array([0.1, -0.2, 0.3, 0.04]), force=1.5,
                    truth=np.zeros(8), applied=np.array([0.007, -2.5]))
    msgs = codecs.SensorMessages(Sensors()).fill(sample, 500_000_000)
    expected = [0.1, -0.2, 0.3, 0.04, 1.5, -2.5]
    for spec, msg, value in zip(codecs.SAMPLE_TOPICS, msgs, expected, strict=True):
        assert spec.field and at(msg, spec.field) == value, spec.name
    for channel, msg in enumerate(msgs[:5]):  # and the codec reads them back from there
        assert codecs.sensor_reading(channel, msg) == at(msg, codecs.SENSOR_TOPICS[channel].field)


@pytest.mark.parametrize("actuator", [0, 1])
def test_the_command_codec_writes_into_the_contracts_field(actuator: int) -> None:
    msg = codecs.CommandMessage(actuator).fill(Command(t=1.0, torque=0.03, force=-4.0), 1)
    spec = codecs.COMMAND_TOPICS[actuator]
    assert at(msg, spec.field) == (0.03, -4.0)[actuator]
    assert codecs.command_value(actuator, msg) == at(msg, spec.field)


def test_bag_channels_default_to_the_contracts_field_under_any_namespace() -> None:
    for spec in topics.CONTRACT:
        if spec.field:
            assert _default_field(f"/rig7/{spec.name}", spec.type_name) == spec.field
    assert _default_field("/elsewhere/wrench", "geometry_msgs/msg/WrenchStamped") \
        == DEFAULT_FIELDS["geometry_msgs/msg/WrenchStamped"] == "wrench.force.x"
