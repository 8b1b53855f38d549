"""Bad input to the node API and the backend choice: clear InputErrors, never tracebacks."""

from __future__ import annotations

import pytest

from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.middleware import api, backend_choice, names
from stillframe.middleware.api import create_node


@pytest.fixture
def node(ros_domain: int):
    node = create_node("checker", namespace="/frame", argv=["test"])
    yield node
    node.destroy_node()


def test_unknown_message_type(node: api.Node) -> None:
    with pytest.raises(InputError, match="unknown message type 'sensor_msgs/msg/Imuu'"):
        node.create_publisher("sensor_msgs/msg/Imuu", "imu", "sensor_data")
    with pytest.raises(InputError, match="unknown message type 'nope'"):
        node.create_subscription("nope", "imu", print, "default")


@pytest.mark.parametrize("topic", ["", "a//b", "a/", "1abc", "a/2b", "a b", "~x", "a-b"])
def test_bad_topic_names(node: api.Node, topic: str) -> None:
    with pytest.raises(InputError, match="invalid topic name"):
        node.create_publisher("std_msgs/msg/Header", topic, "default")


def test_topic_name_resolution_follows_rcl() -> None:
    assert names.resolve_topic("imu", "/frame", "sim") == "/frame/imu"
    assert names.resolve_topic("/clock", "/frame", "sim") == "/clock"
    assert names.resolve_topic("~/state", "/frame", "sim") == "/frame/sim/state"
    assert names.resolve_topic("imu", "/", "sim") == "/imu"


def test_bad_qos_and_timer(node: api.Node) -> None:
    with pytest.raises(InputError, match="unknown QoS profile 'fast'"):
        node.create_publisher("std_msgs/msg/Header", "h", "fast")
    with pytest.raises(InputError, match="QoS depth must be >= 1"):
        node.create_publisher("std_msgs/msg/Header", "h", 0)
    with pytest.raises(InputError, match="timer period must be > 0"):
        node.create_timer(0.0, print)


def test_publishing_the_wrong_type(node: api.Node) -> None:
    pub = node.create_publisher("std_msgs/msg/Header", "h", "default")
    with pytest.raises(InputError, match="takes std_msgs/msg/Header, got sensor_msgs/msg/Imu"):
        pub.publish(messages.new("sensor_msgs/msg/Imu"))


def test_one_topic_one_type(node: api.Node) -> None:
    node.create_publisher("std_msgs/msg/Header", "shared", "default")
    with pytest.raises(InputError, match="already used with type std_msgs/msg/Header"):
        node.create_subscription("sensor_msgs/msg/Imu", "shared", print, "default")


def test_unknown_message_field() -> None:
    with pytest.raises(InputError, match="sensor_msgs/msg/JointState has no field"):
        messages.new("sensor_msgs/msg/JointState", positions=[1.0])


@pytest.mark.parametrize(
    ("name", "namespace", "message"),
    [("9lives", "/", "invalid node name"), ("ok", "/a b", "invalid namespace")],
)
def test_bad_node_name_or_namespace(ros_domain: int, name: str, namespace: str,
                                    message: str) -> None:
    with pytest.raises(InputError, match=message):
        create_node(name, namespace=namespace, argv=["test"])


def test_backend_choice(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(api.BACKEND_ENV, "dds")
    assert api.backend_name() == "dds"
    monkeypatch.setenv(api.BACKEND_ENV, "fastrtps")
    with pytest.raises(InputError, match="STILLFRAME_RMW='fastrtps': expected one of dds, "
                                         "rclpy"):
        api.backend_name()
    monkeypatch.delenv(api.BACKEND_ENV)
    assert api.backend_name() == ("rclpy" if api.has_rclpy() else "dds")
    monkeypatch.setattr(backend_choice, "has_rclpy", lambda: False)  # api re-exports its choice
    assert api.backend_name() == "dds"
    monkeypatch.setenv(api.BACKEND_ENV, "rclpy")
    with pytest.raises(InputError, match="rclpy cannot be imported"):
        api.backend_name()


def test_bad_domain_id(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STILLFRAME_RMW", "dds")
    monkeypatch.setenv("ROS_DOMAIN_ID", "lab")
    with pytest.raises(InputError, match=r"ROS_DOMAIN_ID=.lab.: expected an integer 0\.\.232"):
        create_node("n", argv=["test"])
