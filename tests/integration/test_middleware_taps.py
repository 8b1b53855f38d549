"""Monitor taps on both backends: every sample on the topic, at most one per ``1 / rate_hz`` s
of the tap's clock on the hidden twin topic, and the twin's readers never counted as the
topic's."""

from __future__ import annotations

import itertools

import pytest

from stillframe.contract import messages
from stillframe.middleware import api, names
from stillframe.middleware.qos import DEFAULT, QoSProfile, Reliability
from stillframe.middleware.taps import TAP_PREFIX, TappedPublisher, tap_topic
from tests.support.waits import HANG_S

BACKENDS = ["dds", pytest.param("rclpy", marks=pytest.mark.skipif(
    not api.has_rclpy(), reason="rclpy is not importable here"))]
SAMPLES = 1000
#: the publisher's rate on the fake clock [Hz] and the tap's
PUBLISH_HZ, TAP_HZ = 1000, 50
BEST_EFFORT = QoSProfile(depth=SAMPLES, reliability=Reliability.BEST_EFFORT)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_tap_carries_the_first_sample_of_each_tap_period(
        backend: str, ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """1000 samples at 1 kHz of a clock the test advances: the topic gets all of them, the tap
    exactly samples 0, 20, 40, ... (one per 1/50 s, the first of each 20)."""
    monkeypatch.setenv("STILLFRAME_RMW", backend)
    node = api.create_node("tap_check")
    ticks = itertools.count()
    try:
        pub = TappedPublisher(node, "std_msgs/msg/UInt32", "n", DEFAULT, rate_hz=TAP_HZ,
                              clock=lambda: next(ticks) * 10**9 // PUBLISH_HZ)
        every = node.create_polled_subscription("std_msgs/msg/UInt32", "n",
                                                DEFAULT.with_depth(SAMPLES))
        thinned = node.create_polled_subscription("std_msgs/msg/UInt32", tap_topic("/n"),
                                                  BEST_EFFORT)
        assert pub.topic_name == "/n" and tap_topic("/n") == TAP_PREFIX + "/n"
        assert names.is_hidden(tap_topic("/n")) and not names.is_hidden("/n")
        assert api.spin_until(node, lambda: pub.tap.get_subscription_count() == 1
                              and pub.get_subscription_count() == 1, HANG_S)
        got_every: list[int] = []
        got_thinned: list[int] = []
        for start in range(0, SAMPLES, 50):
            for i in range(start, start + 50):
                pub.publish(messages.new("std_msgs/msg/UInt32", data=i))
            api.spin_until(node, lambda: False, 0.05)
            got_every += [messages.deserialize(d, "std_msgs/msg/UInt32").data
                          for d, _ in every.take()]
            got_thinned += [messages.deserialize(d, "std_msgs/msg/UInt32").data
                            for d, _ in thinned.take()]
        # the tap's reader is not one of the topic's
        assert pub.get_subscription_count() == 1
    finally:
        node.destroy_node()
    assert got_every == list(range(SAMPLES))
    assert got_thinned == list(range(0, SAMPLES, PUBLISH_HZ // TAP_HZ))
