"""Polled subscriptions (the monitor's readers) on both backends: samples wait in the middleware
through spinning, and ``take`` hands them over in order, as many as the KEEP_LAST depth."""

from __future__ import annotations

import pytest

from stillframe.contract import messages
from stillframe.middleware import api
from stillframe.middleware.qos import DEFAULT

BACKENDS = ["dds", pytest.param("rclpy", marks=pytest.mark.skipif(
    not api.has_rclpy(), reason="rclpy is not importable here"))]


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_polled_subscription_keeps_samples_until_taken(
        backend: str, ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STILLFRAME_RMW", backend)
    node = api.create_node("poll_check")
    try:
        pub = node.create_publisher("std_msgs/msg/UInt32", "n", DEFAULT)
        deep = node.create_polled_subscription("std_msgs/msg/UInt32", "n", DEFAULT.with_depth(50))
        newest = node.create_polled_subscription("std_msgs/msg/UInt32", "n",
                                                 DEFAULT.with_depth(1))
        assert api.spin_until(node, lambda: pub.get_subscription_count() == 2, 10)
        assert len(node.get_subscriptions_info_by_topic("/n")) == 2
        for i in range(20):
            pub.publish(messages.new("std_msgs/msg/UInt32", data=i))
        # spinning runs the node's callbacks; a polled subscription has none to run
        api.spin_until(node, lambda: False, 1.0)
        values = [messages.deserialize(data, "std_msgs/msg/UInt32").data
                  for data, _ in deep.take()]
        assert values == list(range(20))
        assert [messages.deserialize(data, "std_msgs/msg/UInt32").data
                for data, _ in newest.take()] == [19]
        assert deep.take() == [] and newest.take() == []
        node.destroy_subscription(deep)
        assert api.spin_until(node, lambda: pub.get_subscription_count() == 1, 10)
    finally:
        node.destroy_node()
