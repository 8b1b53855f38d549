"""The rclpy backend: the same round trip as the dds backend, where ROS 2 is installed.

rclpy cannot be installed from the registries this project reaches (PyPI, Debian), so here
these tests are skipped with that reason; on a workstation with ROS 2 sourced they run.
"""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip(
    "rclpy", reason="rclpy is not importable (not on PyPI/Debian): the rclpy backend is untested"
)

from stillframe.contract import messages  # noqa: E402
from stillframe.middleware.api import create_node, spin_until  # noqa: E402
from stillframe.middleware.qos import SENSOR_DATA, Durability, Reliability  # noqa: E402


def test_round_trip_over_rclpy(ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    node = create_node("rclpy_check", namespace="/frame",
                       argv=["test", "--ros-args", "-p", "gain:=2.5"])
    try:
        assert node.backend == "rclpy"
        assert node.declare_parameter("gain", 1.0).value == 2.5
        got: list = []
        raw: list = []
        pub = node.create_publisher("sensor_msgs/msg/JointState", "js", "default")
        node.create_subscription("sensor_msgs/msg/JointState", "js", got.append, "default")
        node.create_subscription("sensor_msgs/msg/JointState", "js",
                                 lambda data, info: raw.append(data), SENSOR_DATA, raw=True)
        assert spin_until(node, lambda: pub.get_subscription_count() == 2, 10)
        msg = messages.new("sensor_msgs/msg/JointState", name=["phi"], position=[0.5])
        pub.publish(msg)
        assert spin_until(node, lambda: got and raw, 10)
        assert got[0].name == ["phi"] and got[0].position.tolist() == [0.5]
        assert messages.deserialize(raw[0], "sensor_msgs/msg/JointState").position[0] == 0.5
        topics = dict(node.get_topic_names_and_types())
        assert topics["/frame/js"] == ["sensor_msgs/msg/JointState"]
        info = node.get_publishers_info_by_topic("/frame/js")[0]
        assert info.node_name == "rclpy_check"
        # DDS discovery does not carry history or depth: rmw reports them UNKNOWN / 0
        assert info.qos_profile.reliability == Reliability.RELIABLE
        assert info.qos_profile.durability == Durability.VOLATILE
    finally:
        node.destroy_node()
