"""Record topics into a bag: discover publishers, subscribe with an adapted QoS, write CDR bytes.

Like ``ros2 bag record``: topics that appear later are recorded too
(:class:`stillframe.middleware.topic_follower.TopicFollower`); the offered QoS of the publishers
seen on a topic goes into the bag; each message is stamped with its receive time (``/clock``
time with ``sim_time``).

The per-message path is as short as Python allows, so that a recorder beside a 1 kHz loop costs
the loop nothing it would notice. Nothing runs per sample as it arrives: the
subscriptions are *polled* (the middleware's polled subscriptions, KEEP_LAST of at least
:data:`stillframe.middleware.qos.RECORD_DEPTH`): every :data:`POLL_PERIOD_S` the recorder wakes
once, takes the CDR bytes waiting in each DDS reader and appends them to the open MCAP chunk;
the chunk goes to the file when it is full (1 MiB). The DDS readers' histories are the buffer
between receiving and writing that rosbag2 keeps in its double-buffered message cache; nothing is
decoded. An event-driven recorder (one wake-up per sample) would spend its time in the wait
(rmw's wait set, once per sample of every topic under rclpy) and starve the loop it records.

Receive time: each sample keeps the time it arrived (rmw's reception time stamp under rclpy, the
source time stamp under Cyclone, which keeps none), not the time it was taken. A sample the
transport dropped and the reliable writer repaired arrives after samples sent later, and is logged
when it arrived (as rosbag2 logs it): a topic's messages in log-time order can be out of their
publication order, none missing. With ``sim_time`` the recorder does what a callback recorder's
``now()`` does under ``use_sim_time``: a sample is stamped with the latest ``/clock`` that had
arrived before it (0 before the first), worked out from the arrival times of the ``/clock``
samples taken in the same poll. The node itself stays on system time, so rclpy does not run its
``/clock`` callback a thousand times a second.

Nothing is lost in silence. A recorder that is stopped or starved (SIGSTOP, a loaded machine)
receives nothing meanwhile, and the publishers keep only their last few samples for it: the
samples sent meanwhile are gone. The recorder finds them from the stamps: a topic whose messages
start with a time stamp (a ``std_msgs/Header``, or ``/clock``'s time) and whose stamps lie on a
grid (every step between consecutive stamps a multiple of the smallest, as the simulator's
samples at its period) misses ``step / period - 1`` samples at each step longer than the period
(:class:`GapCounter`): lost on the way to the recorder, or never sent (a node that skipped a
sample); the stamps cannot tell which, and the count says "missing". A poll that comes long
after the one before says the recorder stalled. Both are logged as warnings when the recorder
notices them, summed in its last line (:meth:`Recorder.summary`) and written into the bag's
``metadata.yaml`` as ``custom_data`` (the map rosbag2 keeps for its users; ``ros2 bag info``
does not show it): :data:`MISSING_KEY`, a JSON object of the samples missing per topic, one
entry for every topic whose stamps were checked, and :data:`STALLS_KEY`. Publication sequence
numbers are not used: the ``dds`` backend has none, and the ``rclpy`` backend's polled take does
not pass them on and has no writer GID beside them, so two writers of one topic (``/rosout``,
``/diagnostics``) could not be told apart.
"""

from __future__ import annotations

import bisect
import json
import struct
import time
from collections.abc import Mapping, Sequence
from typing import Any

from stillframe.bags.qos import to_bag
from stillframe.bags.storage import BagWriter
from stillframe.contract import messages
from stillframe.middleware.api import MessageInfo
from stillframe.middleware.qos import CLOCK, QoSProfile, recorder_request
from stillframe.middleware.topic_follower import RawCallback, TopicFollower

__all__ = ["MISSING_KEY", "STALLS_KEY", "GapCounter", "Recorder", "SimStamps", "completeness",
           "starts_with_stamp"]

#: how often the recorder takes what its readers hold [s]: 50 wake-ups a second whatever the
#: load; at 1 kHz a reader holds 20 samples of its ``RECORD_DEPTH`` (1000) then
POLL_PERIOD_S = 0.02
CLOCK_TOPIC = "/clock"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
_CLOCK = struct.Struct("<iI")   # builtin_interfaces/Time, first in the CDR after its header
_TIME = "builtin_interfaces/msg/Time"
#: a poll this late after the one before says the recorder stalled [s]
STALL_S = 0.5
#: the smallest grid taken for a period [ns]: stamps closer than that are not a sample grid
MIN_PERIOD_NS = 1000
#: step sizes kept per topic: a stream of stamps with more is not on a grid (a grid with gaps
#: of every length up to a few thousand periods stays under it)
MAX_STEP_SIZES = 4096
#: ``custom_data`` keys of the bag's metadata: samples missing per topic, and the stalls (JSON)
MISSING_KEY = "stillframe.missing_samples"
STALLS_KEY = "stillframe.recorder_stalls"


def starts_with_stamp(msgtype: str) -> bool:
    """Whether a message of ``msgtype`` starts with a ``builtin_interfaces/Time`` (directly,
    as ``/clock``, or as the stamp of a leading ``std_msgs/Header``)."""
    while msgtype in messages.TYPESTORE.fielddefs:
        fields = messages.TYPESTORE.fielddefs[msgtype][1]
        if not fields or fields[0][1][0].name != "NAME":
            return False
        msgtype = fields[0][1][1]
        if msgtype == _TIME:
            return True
    return False


class GapCounter:
    """Samples missing from one topic's stream of stamps (module docstring). The steps between
    consecutive stamps are kept by size (a grid has few sizes: the period, gaps of a few
    periods); the period is the smallest step, and the stream is on a grid when every step is
    a whole number n of periods within n ns (stamps rounded to the nanosecond from a period
    that is not a whole number of them, as 1/1024 s). Stamps of a clock that jitters are not,
    and when they take more than :data:`MAX_STEP_SIZES` sizes they are no longer kept. Repeated
    and earlier stamps (a restarted simulator) are no steps."""

    __slots__ = ("last", "off_grid", "steps")

    def __init__(self) -> None:
        self.last: int | None = None
        #: step size [ns] -> how many steps of that size
        self.steps: dict[int, int] = {}
        self.off_grid = False

    def add(self, stamp_ns: int) -> None:
        """Count the step from the previous stamp to ``stamp_ns`` [ns] by its size; a repeated or
        earlier stamp counts no step, and past :data:`MAX_STEP_SIZES` sizes the stream is off the
        grid and nothing more is counted."""
        last, self.last = self.last, stamp_ns
        if last is None or stamp_ns <= last or self.off_grid:
            return
        steps = self.steps
        step = stamp_ns - last
        steps[step] = steps.get(step, 0) + 1
        if len(steps) > MAX_STEP_SIZES:
            self.off_grid = True

    def missing(self) -> int | None:
        """Samples missing between the first and the last stamp; None when the stamps are not
        on a grid (or too few to tell)."""
        if self.off_grid or not self.steps:
            return None
        period = min(self.steps)
        if period < MIN_PERIOD_NS:
            return None
        total = 0
        for step, count in self.steps.items():
            periods = round(step / period)
            if abs(step - periods * period) > periods:
                return None
            total += (periods - 1) * count
        return total


class SimStamps:
    """Receive times on ``/clock`` from arrival times on the system clock: the latest ``/clock``
    value that had arrived by then (0 before the first), as ``now()`` under ``use_sim_time``."""

    def __init__(self) -> None:
        self._arrivals: list[int] = []
        self._values: list[int] = []
        self._base = 0

    def add(self, cdr: bytes, arrived_ns: int) -> None:
        """Note the ``/clock`` message ``cdr`` (its serialized bytes) that arrived at ``arrived_ns``
        on the system clock."""
        sec, nanosec = _CLOCK.unpack_from(cdr, 4)
        self._arrivals.append(arrived_ns)
        self._values.append(sec * 1_000_000_000 + nanosec)

    def stamp(self, arrived_ns: int) -> int:
        """The sim time [ns] of a sample that arrived at ``arrived_ns``: the latest ``/clock`` that
        had arrived by then (the one kept by :meth:`keep_last` before any, 0 before the first)."""
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
        #: per topic whose messages start with a stamp: its gaps
        self.gaps: dict[str, GapCounter] = {}
        self._said: dict[str, int] = {}
        #: stalls: how many, and the longest [s]
        self.stalls, self.longest_stall_s = 0, 0.0
        self._polled_at: float | None = None
        self._poll_period_s = poll_period_s
        self._sim = SimStamps() if sim_time else None
        # every /clock sample of a poll, not only the newest (the clock profile keeps one)
        self._clock = (node.create_polled_subscription(CLOCK_TYPE, CLOCK_TOPIC,
                                                       recorder_request([CLOCK]))
                       if sim_time else None)
        super().__init__(node, topics, poll_period_s=poll_period_s)

    def on_new_topic(self, topic: str, msgtype: str, offers: list[QoSProfile]) -> RawCallback:
        """Add ``topic`` to the bag with its publishers' ``offers`` and return the callback that
        writes each sample, stamped with its receive time (sim time from ``/clock`` under
        ``use_sim_time``); on a topic whose messages start with a header stamp it also counts the
        gaps of those stamps (:class:`GapCounter`)."""
        self.bag.add_topic(topic, msgtype, [to_bag(q) for q in offers])
        write = self.bag.writer_of(topic)
        sim = self._sim
        if not starts_with_stamp(msgtype):
            def record(data: bytes, info: MessageInfo) -> None:
                write(sim.stamp(info.received_timestamp) if sim else info.received_timestamp,
                      data)

            return record
        gaps = self.gaps[topic] = GapCounter()
        add, unpack = gaps.add, _CLOCK.unpack_from

        def record_stamped(data: bytes, info: MessageInfo) -> None:
            write(sim.stamp(info.received_timestamp) if sim else info.received_timestamp, data)
            if len(data) >= 12:
                sec, nanosec = unpack(data, 4)
                add(sec * 1_000_000_000 + nanosec)

        return record_stamped

    def poll(self) -> int:
        """Take what waits, ``/clock`` first (the stamps of the others come from it); then say
        what went missing since the last poll, and whether the recorder stalled before it."""
        now = time.monotonic()
        if self._polled_at is not None and (late := now - self._polled_at) > STALL_S:
            self.stalls += 1
            self.longest_stall_s = max(self.longest_stall_s, late)
            self.node.get_logger().warning(
                f"recorder stalled: no poll for {late:.2f} s (every {self._poll_period_s:g} s "
                "expected); samples sent meanwhile may be lost")
        self._polled_at = now
        handed = self._take()
        self._say_losses()
        return handed

    def _say_losses(self) -> None:
        """One warning line for the samples found missing since the last one."""
        new = {}
        for topic, gaps in self.gaps.items():
            missing = gaps.missing() or 0
            if missing > self._said.get(topic, 0):
                new[topic] = missing - self._said.get(topic, 0)
                self._said[topic] = missing
        if new:
            self.node.get_logger().warning(
                f"the bag misses {sum(new.values())} samples more (gaps in their topics' stamp "
                "grids: lost on the way or never sent): "
                + ", ".join(f"{t} {n}" for t, n in sorted(new.items())))

    def _take(self) -> int:
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

    def missing_samples(self) -> dict[str, int]:
        """Samples missing per topic whose stamps lie on a grid (0 where none is; topics whose
        stamps could not be checked are absent)."""
        return {topic: missing for topic, gaps in sorted(self.gaps.items())
                if (missing := gaps.missing()) is not None}

    def summary(self) -> str:
        """What the bag lacks, as :func:`completeness` says it ("" when nothing)."""
        return completeness(self.missing_samples(), self.stalls, self.longest_stall_s)

    def write_losses(self) -> None:
        """What is missing, and the stalls, into the bag's metadata (before it closes)."""
        self.bag.custom_data[MISSING_KEY] = json.dumps(self.missing_samples())
        self.bag.custom_data[STALLS_KEY] = json.dumps(
            {"count": self.stalls, "longest_s": round(self.longest_stall_s, 3)})


def completeness(missing: Mapping[str, int], stalls: int, longest_s: float, *,
                 lacks: Mapping[str, int] | None = None) -> str:
    """What a bag lacks, one phrase to follow "the bag": ``is not complete: it misses N
    samples (...)`` when the stamp grids show missing samples, and ``it lacks N more samples the
    simulator published`` for ``lacks``, the samples per topic beyond those (sent before the
    first or after the last sample the bag holds of a topic, which no stamp grid shows: the
    launch knows them from the simulator's count); ``may not be complete: ...`` when the
    recorder only stalled (the topics on a stamp grid miss nothing, but those without one,
    such as ``/rosout`` and ``/diagnostics``, may have lost what was sent meanwhile); "" when
    none of these."""
    missing = {t: n for t, n in missing.items() if n}
    lacks = {t: n for t, n in (lacks or {}).items() if n}
    stalled = (f"the recorder stalled {stalls} times, the longest {longest_s:.2f} s"
               if stalls else "")
    parts = []
    if missing:
        parts.append(f"it misses {sum(missing.values())} samples ("
                     + ", ".join(f"{t} {n}" for t, n in missing.items()) + ")")
    if lacks:
        parts.append(f"it lacks {sum(lacks.values())} more samples the simulator published, "
                     "before the first or after the last it holds of their topics ("
                     + ", ".join(f"{t} {n}" for t, n in lacks.items()) + ")")
    if parts:
        return "is not complete: " + "; ".join(parts) + (f"; {stalled}" if stalled else "")
    if stalled:
        return (f"may not be complete: {stalled}; no sample is missing from the topics on a "
                "stamp grid, topics without one may have lost what was sent meanwhile")
    return ""
