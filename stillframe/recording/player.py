"""Play a bag back: republish each message's CDR bytes with the recorded timing and QoS.

Like ``ros2 bag play``: messages go out in time-stamp order, message k at wall time
``t0 + (stamp_k - stamp_0) / rate``; each topic's publisher offers the QoS its recorded publishers
offered (:func:`stillframe.bags.qos.player_offer`); ``topics`` plays only those, ``exclude``
leaves those out (a name the bag lacks is bad input); with a clock rate, ``/clock`` carries the
bag time, and a ``/clock`` recorded in the bag (``record --all`` beside a simulator) is not
played, so that ``/clock`` has one time base (:attr:`Player.skipped` says why, for the note).
Before exiting, reliable publishers wait until every subscriber acknowledged every message.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from stillframe.bags.qos import player_offer
from stillframe.bags.storage import bag_summary, open_bag
from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.middleware.api import ok
from stillframe.middleware.clock import ClockPublisher
from stillframe.middleware.names import resolve_topic

__all__ = ["Player"]

#: How long the player waits at the end for subscribers to acknowledge (reliable topics).
ACK_TIMEOUT_S = 5.0


class Player:
    """Republishes the bag at ``path`` through ``node``."""

    def __init__(self, node: Any, path: str | Path, rate: float = 1.0,
                 clock_hz: float | None = None, *, topics: Sequence[str] = (),
                 exclude: Sequence[str] = ()) -> None:
        if not rate > 0:
            raise InputError(f"--rate must be > 0, got {rate}")
        if clock_hz is not None and not clock_hz > 0:
            raise InputError(f"--clock rate must be > 0 Hz, got {clock_hz}")
        self.node = node
        self.path = Path(path)
        self.rate = rate
        self.summary = bag_summary(self.path, messages.TYPESTORE)
        #: what checking the bag found (damage, metadata disagreeing with the files)
        self.problems = list(self.summary.problems)
        #: topics of the bag not played although selected, and why (for a note)
        self.skipped: dict[str, str] = {}
        played = self._select(topics, exclude, clock=bool(clock_hz))
        for topic in played:
            if topic.type not in messages.TYPESTORE.fielddefs:
                raise InputError(f"{self.path}: topic {topic.name} has type {topic.type}, "
                                 "which the middleware cannot publish (not a Jazzy standard type)")
        self.publishers = {
            t.name: node.create_publisher(t.type, t.name, player_offer(t.offered_qos))
            for t in played}
        self.published = 0
        #: per topic, messages metadata.yaml counts that the pass could not read and publish
        #: (their type in the storage file disagrees with metadata.yaml's)
        self.dropped: dict[str, int] = {}
        self._wall0: int | None = None  # wall time (monotonic ns) of the pass's first message
        if clock_hz:
            clock = ClockPublisher(node)
            node.create_timer(1.0 / clock_hz, lambda: clock.publish(self.bag_time()))

    def _select(self, topics: Sequence[str], exclude: Sequence[str], *, clock: bool) -> list[Any]:
        """The bag's topics to play: ``topics`` (all if empty) less ``exclude``, less a recorded
        ``/clock`` when the player publishes its own; InputError naming a topic the bag lacks."""
        present = {t.name for t in self.summary.topics}
        for option, names in (("--topics", topics), ("--exclude", exclude)):
            if missing := sorted({resolve_topic(n) for n in names} - present):
                raise InputError(f"play {option}: {', '.join(missing)} not in {self.path} "
                                 f"(its topics: {', '.join(sorted(present))})")
        wanted = ({resolve_topic(n) for n in topics} or present) - {resolve_topic(n)
                                                                    for n in exclude}
        if clock and ClockPublisher.TOPIC in wanted:
            wanted.discard(ClockPublisher.TOPIC)
            self.skipped[ClockPublisher.TOPIC] = (
                "the bag's /clock is not played: --clock publishes the bag time on /clock")
        return [t for t in self.summary.topics if t.name in wanted]

    def bag_time(self) -> int:
        """The bag time (ns) that playback has reached (the start time before playing)."""
        if self._wall0 is None:
            return self.summary.start_ns
        elapsed = (time.monotonic_ns() - self._wall0) * self.rate
        return self.summary.start_ns + min(int(elapsed), self.summary.duration_ns)

    def _sleep_until(self, wall_ns: int) -> None:
        """Run the node's callbacks (``/clock``, discovery) until ``wall_ns`` or shutdown."""
        while ok() and (remaining := wall_ns - time.monotonic_ns()) > 0:
            self.node.spin_once(remaining * 1e-9)

    def wait(self, seconds: float) -> None:
        """Let discovery match the publishers with subscribers before playing (``--delay``)."""
        self._sleep_until(time.monotonic_ns() + int(seconds * 1e9))

    def play_once(self) -> None:
        """One pass through the bag with the original timing divided by the rate."""
        self._wall0 = None
        if not self.publishers:
            return
        read = dict.fromkeys(self.publishers, 0)
        types = {t.name: t.type for t in self.summary.topics}
        with open_bag(self.path, messages.TYPESTORE) as reader:
            # each topic as the type metadata.yaml names (its publisher's): others are counted
            wanted = [c for c in reader.connections
                      if c.topic in self.publishers and c.msgtype == types[c.topic]]
            for connection, stamp, data in reader.messages(wanted) if wanted else ():
                if self._wall0 is None:  # the bag is open: time starts with its first message
                    self._wall0 = time.monotonic_ns()
                self._sleep_until(self._wall0 + int((stamp - self.summary.start_ns)
                                                    / self.rate))
                if not ok():
                    return
                self.publishers[connection.topic].publish(data)
                self.published += 1
                read[connection.topic] += 1
        self.dropped = {t.name: t.count - read[t.name] for t in self.summary.topics
                        if t.name in read and t.count > read[t.name]}

    def dropped_text(self) -> str:
        """One line on what a pass could not publish, by topic ("" if nothing)."""
        types = {t.name: (t.type, t.count) for t in self.summary.topics}
        return "; ".join(
            f"{topic}: {n} of {types[topic][1]} (none of type {types[topic][0]}, as "
            "metadata.yaml says, in the storage file)" if n == types[topic][1] else
            f"{topic}: {n} of {types[topic][1]} (not in the storage file as metadata.yaml "
            "says)" for topic, n in sorted(self.dropped.items()))

    def finish(self) -> bool:
        """Wait (at most ``ACK_TIMEOUT_S`` in all) until subscribers acknowledged everything."""
        deadline = time.monotonic() + ACK_TIMEOUT_S
        return all(pub.wait_for_all_acked(max(0.0, deadline - time.monotonic()))
                   for pub in self.publishers.values())
