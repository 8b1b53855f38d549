"""Follow the ROS graph: subscribe (raw CDR) to every wanted topic as its publishers appear.

Shared by the bag recorder and the Foxglove bridge, like ``ros2 bag record`` and
``foxglove_bridge``: discovery is polled every ``DISCOVERY_PERIOD_S`` on the system clock, so
topics that appear later are picked up too; a topic is taken with its first type if that type is
a Jazzy standard type and no publisher announces a different type hash; the subscription QoS is
adapted to the publishers' offers (:func:`stillframe.bags.qos.recorder_request`).

The recorder takes every topic as soon as it is found. A follower made with ``on_demand``
(the Foxglove bridge) only announces it (:meth:`TopicFollower.on_new_topic`) and subscribes
while something wants it (:meth:`TopicFollower.want`, callable from any thread, applied on the
next discovery pass), as ``foxglove_bridge`` subscribes only to the channels a client
subscribed to: a topic nobody watches costs the publishers and this process nothing.

A follower made with ``read_taps`` (a live view) reads a topic's monitor tap
(:mod:`stillframe.middleware.taps`: the samples thinned by the loop's writers, on a hidden twin
topic) while the tap has a publisher, and the topic itself otherwise; it switches when the tap
appears or goes. Hidden topics (a token starting with ``_``: the taps, ``/_action/``) are taken
only when named, as ``ros2 bag record -a`` leaves them out.

A follower made with ``poll_period_s`` reads by polling (the middleware's polled
subscriptions): nothing runs per sample; every ``poll_period_s`` it takes what waits in each
reader (at most the request's KEEP_LAST depth) and hands it on, taking again until the reader
is empty (a recorder loses nothing). One made with ``newest_only`` as well (a live view, whose
request keeps depth 1) takes once per period and hands on only the newest sample taken: a view
decimated before any work is done on it, at most one sample a period (taking again would let
through a sample that arrived while the one before was handed on).
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

from stillframe.contract import messages
from stillframe.middleware import names
from stillframe.middleware.clock import SYSTEM_CLOCK
from stillframe.middleware.qos import QoSProfile, recorder_request
from stillframe.middleware.taps import tap_topic

DISCOVERY_PERIOD_S = 0.1
#: on shutdown, keep handing on what arrives until nothing came for this long [s]
DRAIN_QUIET_S = 0.2
DRAIN_POLL_S = 0.005
#: the drain's end at the latest [s]: a peer that keeps publishing (``ros2 topic pub`` at 10 Hz
#: beside a recorder of every topic) never leaves it quiet, and the launch that stops the
#: recorder gives it 10 s before SIGTERM
DRAIN_MAX_S = 2.0
#: what a subclass returns for a new topic: the raw callback ``(cdr_bytes, MessageInfo)``
RawCallback = Callable[[bytes, Any], None]


class TopicFollower:
    """Subscribes ``node`` to ``topics`` (all ROS topics if empty) as they are discovered;
    :meth:`on_new_topic` says where each topic's samples go."""

    def __init__(self, node: Any, topics: Sequence[str] = (), on_demand: bool = False,
                 poll_period_s: float | None = None, read_taps: bool = False, *,
                 newest_only: bool = False) -> None:
        self.node = node
        self.topics = set(topics)
        self.on_demand = on_demand
        self.polled = poll_period_s is not None
        self.newest_only = newest_only
        self.read_taps = read_taps
        #: topic -> (type, publishers' offers, callback) of every topic taken
        self._found: dict[str, tuple[str, list[QoSProfile], RawCallback]] = {}
        #: topic -> (the topic read for it: itself or its tap, subscription)
        self._subscriptions: dict[str, tuple[str, Any]] = {}
        self._wanted: Counter[str] = Counter()
        self._wanted_lock = threading.Lock()
        self.node.create_timer(DISCOVERY_PERIOD_S, self.discover, clock=SYSTEM_CLOCK)
        if poll_period_s is not None:
            self.node.create_timer(poll_period_s, self.poll, clock=SYSTEM_CLOCK)

    def on_new_topic(self, topic: str, msgtype: str, offers: list[QoSProfile]) -> RawCallback:
        """The raw callback of a newly found ``topic`` of type ``msgtype`` whose publishers offer
        ``offers``: what each subclass does with its samples (write them to a bag, forward them,
        keep the newest)."""
        raise NotImplementedError

    def request(self, offers: list[QoSProfile]) -> QoSProfile:
        """The subscription QoS for a topic with these publishers' ``offers``."""
        return recorder_request(offers)

    def want(self, topic: str, wanted: bool) -> None:
        """One more (``wanted``) or one fewer watcher of ``topic`` (``on_demand`` followers
        subscribe while it has any); thread-safe, takes effect on the next discovery pass."""
        with self._wanted_lock:
            self._wanted[topic] += 1 if wanted else -1

    def discover(self) -> None:
        """Take every wanted topic that has a publisher and is not taken yet; then subscribe to
        the topics taken and watched (to their taps where read), and unsubscribe from those no
        longer watched."""
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._found or (topic not in self.topics if self.topics
                                        else names.is_hidden(topic)):
                continue
            publishers = self.node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # only subscribers so far
            msgtype = types[0]
            if not self._usable(topic, types, publishers):
                continue
            offers = [info.qos_profile for info in publishers]
            self._found[topic] = (msgtype, offers, self.on_new_topic(topic, msgtype, offers))
        with self._wanted_lock:
            watched = {topic for topic, n in self._wanted.items() if n > 0}
        log = self.node.get_logger()
        for topic, (msgtype, offers, callback) in self._found.items():
            wanted = topic in watched or not self.on_demand
            tap_offers = self._tap_offers(topic) if wanted else []
            source = (tap_topic(topic) if tap_offers else topic) if wanted else None
            if (current := self._subscriptions.get(topic)) and current[0] != source:
                self.node.destroy_subscription(self._subscriptions.pop(topic)[1])
                log.info(f"Unsubscribed from topic '{current[0]}'"
                         + ("" if wanted else " (not watched)"))
            if source is not None and topic not in self._subscriptions:
                qos = self.request(tap_offers or offers)
                self._subscriptions[topic] = (source, (
                    self.node.create_polled_subscription(msgtype, source, qos) if self.polled
                    else self.node.create_subscription(msgtype, source, callback, qos, raw=True)))
                log.info(f"Subscribed to topic '{source}'")

    def _tap_offers(self, topic: str) -> list[QoSProfile]:
        """The offers of ``topic``'s tap if this follower reads taps and one is published."""
        if not self.read_taps:
            return []
        return [info.qos_profile
                for info in self.node.get_publishers_info_by_topic(tap_topic(topic))]

    def poll(self) -> int:
        """Hand on what waits in each polled subscription (taking until it is empty; with
        ``newest_only`` the newest sample of one take); the number of samples handed on."""
        handed = 0
        for topic, (_, sub) in list(self._subscriptions.items()):
            callback = self._found[topic][2]
            samples = sub.take()[-1:] if self.newest_only else [
                sample for taken in iter(sub.take, []) for sample in taken]
            for data, info in samples:
                callback(data, info)
            handed += len(samples)
        return handed

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
        :data:`DRAIN_QUIET_S` (samples in flight when the signal came are kept), at most
        :data:`DRAIN_MAX_S`. The ``dds`` backend's subscriptions can be asked for them directly;
        under rclpy, what rclpy delivered before shutdown is all there is. A polled follower
        polls (on either backend) until nothing came."""
        takers = [self.poll] if self.polled else [
            take for _, sub in self._subscriptions.values()
            if (take := getattr(sub, "take_and_dispatch", None)) is not None]
        quiet_since = time.monotonic()
        end = quiet_since + DRAIN_MAX_S
        while takers and (now := time.monotonic()) - quiet_since < DRAIN_QUIET_S and now < end:
            if sum(take() for take in takers):
                quiet_since = time.monotonic()
            else:
                time.sleep(DRAIN_POLL_S)

    def missing(self) -> list[str]:
        """Requested topics never seen with a publisher."""
        return sorted(self.topics - set(self._found))
