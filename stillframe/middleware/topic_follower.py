"""Follow the ROS graph: subscribe (raw CDR) to every wanted topic as its publishers appear.

Shared by the bag recorder and the Foxglove bridge, like ``ros2 bag record`` and
``foxglove_bridge``: discovery is polled every ``DISCOVERY_PERIOD_S`` on the system clock, so
topics that appear later are picked up too; a topic is taken with its first type if that type is
a Jazzy standard type and no publisher announces a different type hash; the subscription QoS is
adapted to the publishers' offers (:func:`stillframe.bags.qos.recorder_request`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

from stillframe.contract import messages
from stillframe.middleware.clock import SYSTEM_CLOCK
from stillframe.middleware.qos import QoSProfile, recorder_request

DISCOVERY_PERIOD_S = 0.1
#: on shutdown, keep handing on what arrives until nothing came for this long [s]
DRAIN_QUIET_S = 0.2
DRAIN_POLL_S = 0.005
#: what a subclass returns for a new topic: the raw callback ``(cdr_bytes, MessageInfo)``
RawCallback = Callable[[bytes, Any], None]


class TopicFollower:
    """Subscribes ``node`` to ``topics`` (all ROS topics if empty) as they are discovered;
    :meth:`on_new_topic` says where each topic's samples go."""

    def __init__(self, node: Any, topics: Sequence[str] = ()) -> None:
        self.node = node
        self.topics = set(topics)
        self._subscriptions: dict[str, Any] = {}
        self.node.create_timer(DISCOVERY_PERIOD_S, self.discover, clock=SYSTEM_CLOCK)

    def on_new_topic(self, topic: str, msgtype: str, offers: list[QoSProfile]) -> RawCallback:
        raise NotImplementedError

    def request(self, offers: list[QoSProfile]) -> QoSProfile:
        """The subscription QoS for a topic with these publishers' ``offers``."""
        return recorder_request(offers)

    def discover(self) -> None:
        """Subscribe to every wanted topic that has a publisher and is not followed yet."""
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._subscriptions or (self.topics and topic not in self.topics):
                continue
            publishers = self.node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # only subscribers so far
            msgtype = types[0]
            if not self._usable(topic, types, publishers):
                continue
            offers = [info.qos_profile for info in publishers]
            callback = self.on_new_topic(topic, msgtype, offers)
            self._subscriptions[topic] = self.node.create_subscription(
                msgtype, topic, callback, self.request(offers), raw=True)
            self.node.get_logger().info(f"Subscribed to topic '{topic}'")

    def _usable(self, topic: str, types: list[str], publishers: list[Any]) -> bool:
        """A topic is taken with its first type if that type is a Jazzy standard type and no
        publisher announces a different type hash (its bytes would not match the definition
        we hold); otherwise warn once."""
        log = self.node.get_logger()
        if len(types) > 1:
            log.warning(f"{topic} has several types {types}; taking {types[0]}", once=True)
        if types[0] not in messages.TYPESTORE.fielddefs:
            log.warning(f"{topic}: type {types[0]} is not a Jazzy standard type; not taken",
                        once=True)
            return False
        ours = messages.type_hash(types[0])
        announced = {p.topic_type_hash for p in publishers if p.topic_type_hash.startswith("RIHS")}
        if others := sorted(announced - {ours}):
            log.warning(f"{topic}: publishers announce type hash {', '.join(others)}, not "
                        f"Jazzy's {ours} for {types[0]}; not taken", once=True)
            return False
        return True

    def drain(self) -> None:
        """After shutdown was requested (``spin`` no longer takes samples): hand on the samples
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

    def missing(self) -> list[str]:
        """Requested topics never seen with a publisher."""
        return sorted(self.topics - set(self._subscriptions))
