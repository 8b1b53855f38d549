"""Record topics into a bag: discover publishers, subscribe with an adapted QoS, write CDR bytes.

Like ``ros2 bag record``: discovery is polled (every ``DISCOVERY_PERIOD_S``) so topics that appear
later are recorded too; the offered QoS of the publishers seen on a topic goes into the bag;
each message is stamped with its receive time on the node's clock (``/clock`` time when the node
uses sim time; discovery still runs on the system clock).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from stillframe import messages
from stillframe.bag_qos import recorder_request, to_bag
from stillframe.bags import BagWriter
from stillframe.middleware.api import MessageInfo
from stillframe.middleware.clock import SYSTEM_CLOCK

DISCOVERY_PERIOD_S = 0.1
#: on shutdown, keep writing what arrives until nothing came for this long [s]
DRAIN_QUIET_S = 0.2
DRAIN_POLL_S = 0.005


class Recorder:
    """Subscribes ``node`` to ``topics`` (all ROS topics if empty) and writes them to ``bag``."""

    def __init__(self, node: Any, bag: BagWriter, topics: Sequence[str] = ()) -> None:
        self.node = node
        self.bag = bag
        self.topics = set(topics)
        self._subscriptions: dict[str, Any] = {}
        self.total = 0
        self.node.create_timer(DISCOVERY_PERIOD_S, self.discover, clock=SYSTEM_CLOCK)

    def discover(self) -> None:
        """Subscribe to every wanted topic that has a publisher and is not recorded yet."""
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._subscriptions or (self.topics and topic not in self.topics):
                continue
            publishers = self.node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # only subscribers so far
            msgtype = types[0]
            if not self._recordable(topic, types, publishers):
                continue
            offers = [info.qos_profile for info in publishers]
            self.bag.add_topic(topic, msgtype, [to_bag(q) for q in offers])
            self._subscriptions[topic] = self.node.create_subscription(
                msgtype, topic, self._writer_for(topic), recorder_request(offers), raw=True)
            self.node.get_logger().info(f"Subscribed to topic '{topic}'")

    def _recordable(self, topic: str, types: list[str], publishers: list[Any]) -> bool:
        """A topic is recorded with its first type if that type is a Jazzy standard type and no
        publisher announces a different type hash (its bytes would not match the definition
        written into the bag); otherwise warn once."""
        log = self.node.get_logger()
        if len(types) > 1:
            log.warning(f"{topic} has several types {types}; recording {types[0]}", once=True)
        if types[0] not in messages.TYPESTORE.fielddefs:
            log.warning(f"{topic}: type {types[0]} is not a Jazzy standard type; not recorded",
                        once=True)
            return False
        ours = messages.type_hash(types[0])
        announced = {p.topic_type_hash for p in publishers if p.topic_type_hash.startswith("RIHS")}
        if others := sorted(announced - {ours}):
            log.warning(f"{topic}: publishers announce type hash {', '.join(others)}, not "
                        f"Jazzy's {ours} for {types[0]}; not recorded", once=True)
            return False
        return True

    def _writer_for(self, topic: str) -> Any:
        def write(data: bytes, info: MessageInfo) -> None:
            self.bag.write(topic, info.received_timestamp, data)
            self.total += 1

        return write

    def drain(self) -> None:
        """After shutdown was requested (``spin`` no longer takes samples): write the samples
        the middleware has received, and those still arriving, until none came for
        :data:`DRAIN_QUIET_S` (samples in flight when the signal came are kept). The ``dds``
        backend's subscriptions can be asked for them directly; under rclpy, what rclpy
        delivered before shutdown is all there is."""
        takers = [take for sub in self._subscriptions.values()
                  if (take := getattr(sub, "take_and_dispatch", None)) is not None]
        quiet_since = time.monotonic()
        while takers and time.monotonic() - quiet_since < DRAIN_QUIET_S:
            if sum(take() for take in takers):
                quiet_since = time.monotonic()
            else:
                time.sleep(DRAIN_POLL_S)

    def counts(self) -> dict[str, int]:
        """Messages written per topic."""
        return {topic: self.bag.count(topic) for topic in sorted(self._subscriptions)}

    def missing(self) -> list[str]:
        """Requested topics never seen with a publisher."""
        return sorted(self.topics - set(self._subscriptions))
