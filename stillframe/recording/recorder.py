"""Record topics into a bag: discover publishers, subscribe with an adapted QoS, write CDR bytes.

Like ``ros2 bag record``: topics that appear later are recorded too
(:class:`stillframe.middleware.topic_follower.TopicFollower`); the offered QoS of the publishers
seen on a topic goes into the bag; each message is stamped with its receive time (``/clock``
time with ``sim_time``).

The per-message path is as short as Python allows, so that a recorder beside a 1 kHz loop costs
the loop nothing it would notice (issue 32). Nothing runs per sample as it arrives: the
subscriptions are *polled* (the middleware's polled subscriptions, KEEP_LAST of at least
:data:`stillframe.middleware.qos.RECORD_DEPTH`): every :data:`POLL_PERIOD_S` the recorder wakes
once, takes the CDR bytes waiting in each DDS reader and appends them to the open MCAP chunk;
the chunk goes to the file when it is full (1 MiB). The DDS readers' histories are the buffer
between receiving and writing that rosbag2 keeps in its double-buffered message cache; nothing is
decoded. An event-driven recorder (one wake-up per sample, as before) spent its time in the
wait (rmw's wait set, 14 000 times a second under rclpy) and starved the loop it recorded.

Receive time: each sample keeps the time it arrived (rmw's reception time stamp under rclpy, the
source time stamp under Cyclone, which keeps none), not the time it was taken. With ``sim_time``
the recorder does what a callback recorder's ``now()`` does under ``use_sim_time``: a sample is
stamped with the latest ``/clock`` that had arrived before it (0 before the first), worked out
from the arrival times of the ``/clock`` samples taken in the same poll. The node itself stays
on system time, so rclpy does not run its ``/clock`` callback a thousand times a second.
"""

from __future__ import annotations

import bisect
import struct
from collections.abc import Sequence
from typing import Any

from stillframe.bags.qos import to_bag
from stillframe.bags.storage import BagWriter
from stillframe.middleware.api import MessageInfo
from stillframe.middleware.qos import CLOCK, QoSProfile, recorder_request
from stillframe.middleware.topic_follower import RawCallback, TopicFollower

#: how often the recorder takes what its readers hold [s]: 50 wake-ups a second whatever the
#: load; at 1 kHz a reader holds 20 samples of its ``RECORD_DEPTH`` (1000) then
POLL_PERIOD_S = 0.02
CLOCK_TOPIC = "/clock"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
_CLOCK = struct.Struct("<iI")   # builtin_interfaces/Time, first in the CDR after its header


class SimStamps:
    """Receive times on ``/clock`` from arrival times on the system clock: the latest ``/clock``
    value that had arrived by then (0 before the first), as ``now()`` under ``use_sim_time``."""

    def __init__(self) -> None:
        self._arrivals: list[int] = []
        self._values: list[int] = []
        self._base = 0

    def add(self, cdr: bytes, arrived_ns: int) -> None:
        sec, nanosec = _CLOCK.unpack_from(cdr, 4)
        self._arrivals.append(arrived_ns)
        self._values.append(sec * 1_000_000_000 + nanosec)

    def stamp(self, arrived_ns: int) -> int:
        i = bisect.bisect_right(self._arrivals, arrived_ns)
        return self._values[i - 1] if i else self._base

    def keep_last(self) -> None:
        """Forget all but the latest ``/clock`` (after a poll: later samples arrive after it)."""
        if self._values:
            self._base = self._values[-1]
            del self._arrivals[:-1], self._values[:-1]


class Recorder(TopicFollower):
    """Subscribes ``node`` to ``topics`` (all ROS topics if empty) and writes them to ``bag``;
    with ``sim_time`` messages are stamped on ``/clock`` (``node`` itself on system time)."""

    def __init__(self, node: Any, bag: BagWriter, topics: Sequence[str] = (), *,
                 sim_time: bool = False, poll_period_s: float = POLL_PERIOD_S) -> None:
        self.bag = bag
        self.total = 0
        self._sim = SimStamps() if sim_time else None
        # every /clock sample of a poll, not only the newest (the clock profile keeps one)
        self._clock = (node.create_polled_subscription(CLOCK_TYPE, CLOCK_TOPIC,
                                                       recorder_request([CLOCK]))
                       if sim_time else None)
        super().__init__(node, topics, poll_period_s=poll_period_s)

    def on_new_topic(self, topic: str, msgtype: str, offers: list[QoSProfile]) -> RawCallback:
        self.bag.add_topic(topic, msgtype, [to_bag(q) for q in offers])
        write = self.bag.writer_of(topic)
        sim = self._sim

        def record(data: bytes, info: MessageInfo) -> None:
            write(sim.stamp(info.received_timestamp) if sim else info.received_timestamp, data)

        return record

    def poll(self) -> int:
        """Take what waits, ``/clock`` first (the stamps of the others come from it)."""
        if self._sim is not None:
            while taken := self._clock.take():
                for data, info in taken:
                    self._sim.add(data, info.received_timestamp)
        handed = super().poll()
        self.total += handed
        if self._sim is not None:
            self._sim.keep_last()
        return handed

    def counts(self) -> dict[str, int]:
        """Messages written per topic."""
        return {topic: self.bag.count(topic) for topic in sorted(self._subscriptions)}
