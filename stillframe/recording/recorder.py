"""Record topics into a bag: discover publishers, subscribe with an adapted QoS, write CDR bytes.

Like ``ros2 bag record``: topics that appear later are recorded too
(:class:`stillframe.middleware.topic_follower.TopicFollower`); the offered QoS of the publishers
seen on a
topic goes into the bag; each message is stamped with its receive time on the node's clock
(``/clock`` time when the node uses sim time; discovery still runs on the system clock).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from stillframe.bags.qos import to_bag
from stillframe.bags.storage import BagWriter
from stillframe.middleware.api import MessageInfo
from stillframe.middleware.qos import QoSProfile
from stillframe.middleware.topic_follower import RawCallback, TopicFollower


class Recorder(TopicFollower):
    """Subscribes ``node`` to ``topics`` (all ROS topics if empty) and writes them to ``bag``."""

    def __init__(self, node: Any, bag: BagWriter, topics: Sequence[str] = ()) -> None:
        self.bag = bag
        self.total = 0
        super().__init__(node, topics)

    def on_new_topic(self, topic: str, msgtype: str, offers: list[QoSProfile]) -> RawCallback:
        self.bag.add_topic(topic, msgtype, [to_bag(q) for q in offers])

        def write(data: bytes, info: MessageInfo) -> None:
            self.bag.write(topic, info.received_timestamp, data)
            self.total += 1

        return write

    def counts(self) -> dict[str, int]:
        """Messages written per topic."""
        return {topic: self.bag.count(topic) for topic in sorted(self._subscriptions)}
