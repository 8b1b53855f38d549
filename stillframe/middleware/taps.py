"""Monitor taps: a per-sample topic thinned at its writer, on a hidden twin topic, for live views.

A live view (``stillframe monitor``, its dashboard) shows a few dozen samples a second; the loop
publishes a thousand. Every reader of a topic costs its writer one send per sample, whatever the
reader keeps: DDS's TIME_BASED_FILTER is applied at the reader in Cyclone, so a monitor reading
the loop's topics, even one that wakes only 50 times a second, makes each of the loop's writes
dearer (docs/monitor.md has the figures and the command that prints them).

So the loop's per-sample publishers are :class:`TappedPublisher`\\ s: every sample goes to the
topic, and the first sample after each ``1 / TAP_RATE_HZ`` s of wall time goes to a twin topic,
``/_monitor<topic>``, best effort, the newest only. A token starting with ``_`` makes a ROS 2 name
hidden (``ros2 topic list`` and ``ros2 bag record -a`` leave it out, as they do ``/_action/``
topics). A view reads a topic's tap when one is published and it wants no more than
``TAP_RATE_HZ``, and the topic itself otherwise (another publisher, a bag played back, every
sample asked for); the loop then sends it one sample in twenty at 1 kHz.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from stillframe.middleware.qos import QoSProfile, Reliability

TAP_PREFIX = "/_monitor"
#: samples a second a tap carries at most (the monitor's default ``--max-rate``)
TAP_RATE_HZ = 50.0
#: the newest sample, best effort: a tap never makes its writer wait for a viewer
TAP_QOS = QoSProfile(depth=1, reliability=Reliability.BEST_EFFORT)


def tap_topic(topic: str) -> str:
    """The hidden twin of the absolute ``topic`` that carries its thinned samples."""
    return TAP_PREFIX + topic


class TappedPublisher:
    """A publisher of ``topic`` whose every ``publish`` also goes to ``tap_topic(topic)`` when
    ``1 / rate_hz`` s of ``clock`` (monotonic nanoseconds) have passed since the last one there."""

    def __init__(self, node: Any, type_name: str, topic: str, qos: QoSProfile | str | int,
                 rate_hz: float = TAP_RATE_HZ,
                 clock: Callable[[], int] = time.monotonic_ns) -> None:
        self.publisher = node.create_publisher(type_name, topic, qos)
        self.tap = node.create_publisher(type_name, tap_topic(self.publisher.topic_name),
                                         TAP_QOS)
        self.topic_name: str = self.publisher.topic_name
        self._period_ns = round(1e9 / rate_hz)
        self._clock = clock
        self._tap_due_ns: int | None = None

    def publish(self, msg: Any) -> None:
        """Publish ``msg`` (a message or its CDR bytes) on the topic, and on the tap if due."""
        self.publisher.publish(msg)
        now = self._clock()
        if self._tap_due_ns is None or now >= self._tap_due_ns:
            self.tap.publish(msg)
            self._tap_due_ns = now + self._period_ns

    def get_subscription_count(self) -> int:
        """Readers of the topic (the tap's are not counted: a view never holds the loop)."""
        return self.publisher.get_subscription_count()

    def wait_for_all_acked(self, timeout_sec: float) -> bool:
        return self.publisher.wait_for_all_acked(timeout_sec)
