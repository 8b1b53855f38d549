"""Polled subscriptions (the monitor's readers) on both backends: samples wait in the middleware
through spinning, and ``take`` hands them over in order, as many as the KEEP_LAST depth; a
follower that polls them hands on all (a recorder) or only the newest (a live view)."""

from __future__ import annotations

import pytest

from stillframe.contract import messages
from stillframe.middleware import api
from stillframe.middleware.qos import DEFAULT, QoSProfile
from stillframe.middleware.topic_follower import RawCallback, TopicFollower
from tests.support.waits import HANG_S

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
        assert api.spin_until(node, lambda: pub.get_subscription_count() == 2, HANG_S)
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
        assert api.spin_until(node, lambda: pub.get_subscription_count() == 1, HANG_S)
    finally:
        node.destroy_node()


class Kept(TopicFollower):
    """Follows ``/n`` with a deep reader, polled only when the test polls; keeps the values
    handed on, a list per poll."""

    def __init__(self, node: api.Node, *, newest_only: bool) -> None:
        self.polls: list[list[int]] = []
        super().__init__(node, ["/n"], poll_period_s=3600.0, newest_only=newest_only)

    def request(self, offers: list) -> QoSProfile:
        return DEFAULT.with_depth(50)

    def on_new_topic(self, topic: str, msgtype: str, offers: list) -> RawCallback:
        return lambda data, _: self.polls[-1].append(messages.deserialize(data, msgtype).data)

    def poll(self) -> int:
        self.polls.append([])
        return super().poll()


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_live_view_hands_on_the_newest_sample_once_a_poll(
        backend: str, ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """With 20 samples waiting in each reader (deeper than a live view keeps, to force what a
    sample arriving during a poll does), a recorder's follower hands on all 20 in one poll, a
    live view's (``newest_only``, the monitor's) only the newest, and nothing at the next."""
    monkeypatch.setenv("STILLFRAME_RMW", backend)
    node = api.create_node("follow_check")
    try:
        pub = node.create_publisher("std_msgs/msg/UInt32", "n", DEFAULT)
        every, view = Kept(node, newest_only=False), Kept(node, newest_only=True)
        assert api.spin_until(node, lambda: pub.get_subscription_count() == 2, HANG_S)
        for i in range(20):
            pub.publish(messages.new("std_msgs/msg/UInt32", data=i))

        def all_handed() -> bool:
            """Both readers are the one node's: what one has received, the other has."""
            every.poll()
            return sum(map(len, every.polls)) >= 20

        assert api.spin_until(node, all_handed, HANG_S)
        assert [v for values in every.polls for v in values] == list(range(20))
        assert max(map(len, every.polls)) > 1      # several waited at one poll, all handed on
        assert view.poll() == 1 and view.poll() == 0
        assert view.polls == [[19], []]
    finally:
        node.destroy_node()
