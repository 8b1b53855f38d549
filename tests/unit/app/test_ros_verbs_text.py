"""The text of the ros2-like verbs that needs no graph: ``interface show`` against rosbags'
Jazzy typestore, ``topic hz``'s stale line, ``topic pub``'s YAML."""

from __future__ import annotations

from collections import deque

import pytest
from rosbags.typesys import Stores, get_typestore

from stillframe.app.commands.interface import definition
from stillframe.app.commands.topic import hz_line, message_repr
from stillframe.contract.message_yaml import from_yaml
from stillframe.errors import InputError

JAZZY = get_typestore(Stores.ROS2_JAZZY)


@pytest.mark.parametrize("name", ["sensor_msgs/msg/Imu", "geometry_msgs/msg/WrenchStamped",
                                  "std_msgs/msg/Float64MultiArray", "sensor_msgs/msg/BatteryState",
                                  "diagnostic_msgs/msg/DiagnosticArray"])
def test_interface_show_is_the_typestores_definition(name: str) -> None:
    shown = definition(name).splitlines()
    text = JAZZY.generate_msgdef(name, ros_version=2)[0]
    own, *nested = text.split("=" * 80 + "\n")
    # the lines at depth 0 are the type's own definition, line for line
    assert [line for line in shown if not line.startswith("\t")] == own.splitlines()
    # each nested block is the typestore's definition of that field's type, one tab deeper
    bodies = {part.split("\n", 1)[0].removeprefix("MSG: "): part.split("\n", 1)[1].splitlines()
              for part in nested}
    def depth(line: str) -> int:
        return len(line) - len(line.lstrip("\t"))

    checked = 0
    for i, line in enumerate(shown):
        field_type = line.strip().split(" ")[0].split("[")[0]
        if field_type in bodies:
            block = []
            for below in shown[i + 1:]:
                if depth(below) <= depth(line):
                    break
                block.append(below)
            assert [b.strip() for b in block if depth(b) == depth(line) + 1] == bodies[field_type]
            checked += 1
    assert checked >= len(bodies)


def test_interface_show_of_a_service_and_of_nothing() -> None:
    text = definition("rcl_interfaces/srv/GetParameters")
    request, response = text.split("\n---\n")
    assert request == "string[] names"
    assert response.startswith("rcl_interfaces/ParameterValue[] values\n\tuint8 type")
    with pytest.raises(InputError, match="did you mean sensor_msgs/msg/Imu"):
        definition("sensor_msgs/msg/Imuu")


def test_hz_says_no_new_messages_instead_of_stale_figures() -> None:
    stamps = deque([0, 10_000_000, 20_000_000])
    first = hz_line(stamps, reported=0)
    assert first.startswith("average rate: 100.000")
    assert hz_line(stamps, reported=20_000_000) == "no new messages"
    assert hz_line(deque(), reported=0) == "no new messages"


def test_pub_yaml_fills_a_message_like_ros2_topic_pub() -> None:
    stampers: list = []
    msg = from_yaml("geometry_msgs/msg/WrenchStamped",
                    {"header": "auto", "wrench": {"torque": {"z": 2}}}, stampers=stampers)
    assert msg.wrench.torque.z == 2.0 and isinstance(msg.wrench.torque.z, float)
    stampers[0](7_000_000_005)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (7, 5)
    assert message_repr(from_yaml("std_msgs/msg/Float64", {"data": 0.5})) == (
        "std_msgs.msg.Float64(data=0.5)")
    for values, message in (({"data": "x"}, "expected a number"), ({"dat": 1}, "no field 'dat'"),
                            ([1], "expected a mapping")):
        with pytest.raises(InputError, match=message):
            from_yaml("std_msgs/msg/Float64", values)
    with pytest.raises(InputError, match="expected 9 values"):
        from_yaml("sensor_msgs/msg/Imu", {"orientation_covariance": [0.0]})
