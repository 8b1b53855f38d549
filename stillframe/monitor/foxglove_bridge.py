"""Bridge the ROS graph to the Foxglove WebSocket protocol (``foxglove.websocket.v1``).

Like ``foxglove_bridge``, on whichever backend the node runs: every discovered topic
(:class:`stillframe.middleware.topic_follower.TopicFollower`) becomes a ``foxglove-sdk`` channel
with schema encoding ``ros2msg`` (the ``.msg`` definition with its dependencies, as ``rosbags``
writes it into MCAP bags) and message encoding ``cdr``; the CDR bytes pass through unconverted. With
sim time, the newest ``/clock`` is broadcast as the server time after each poll (capability
``time``), which drives Foxglove's and Lichtblick's time cursor, and it is the log time of the
messages forwarded in the next poll. ``/clock`` is followed like the topics, always watched (a node
with ``use_sim_time`` would decode every one of a 1 kHz loop's ``/clock`` samples). The SDK keeps a
bounded queue per client and drops a slow client's oldest messages, so no client can hold the node
back.

Every topic is advertised as soon as it is found, but subscribed to only while a client
subscribes to its channel (the server's ``on_subscribe``/``on_unsubscribe``, counted over the
clients), like ``foxglove_bridge``: a topic no client watches costs neither its publisher nor
the monitor anything.

A live view is forwarded at most ``max_rate_hz`` samples per second per topic: the
subscriptions are polled (KEEP_LAST 1, taken every ``1 / max_rate_hz`` s), so the monitor does
no work for the samples in between, and a 1 kHz loop is not slowed by a Python process waking
a thousand times a second per topic (docs/monitor.md has the figures). Up to
:data:`~stillframe.middleware.taps.TAP_RATE_HZ` the loop's topics are read from their monitor
taps, thinned by the loop's own writers, so the loop does not send the monitor every sample
either. ``max_rate_hz = 0`` forwards every sample (polled every :data:`EVERY_SAMPLE_POLL_S`, from a
deep queue); a bag (``stillframe record``) has every sample too, for Foxglove to open after.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import foxglove

from stillframe.contract import messages
from stillframe.middleware.api import MessageInfo
from stillframe.middleware.clock import ClockPublisher
from stillframe.middleware.qos import QoSProfile, viewer_request
from stillframe.middleware.taps import TAP_RATE_HZ
from stillframe.middleware.topic_follower import RawCallback, TopicFollower

__all__ = ["FoxgloveBridge", "ros2msg_schema"]

SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
#: outgoing messages buffered per client before the oldest are dropped
CLIENT_BACKLOG = 1024
#: how often every waiting sample is taken when every sample is forwarded [s]
EVERY_SAMPLE_POLL_S = 0.02


def ros2msg_schema(msgtype: str) -> foxglove.Schema:
    """The ``ros2msg`` schema of a type: its definition and its dependencies' after
    ``MSG:`` separators (``rosbags``'s ``generate_msgdef``, the text of rosbag2's MCAP files)."""
    text, _ = messages.TYPESTORE.generate_msgdef(msgtype, ros_version=2)
    return foxglove.Schema(name=msgtype, encoding=SCHEMA_ENCODING, data=text.encode())


class FoxgloveBridge(TopicFollower):
    """Serves ``topics`` (every topic if empty) of ``node`` to Foxglove clients on
    ``host:port`` (``self.server``; raises RuntimeError if it cannot listen there), at most
    ``max_rate_hz`` samples per second and topic (0: every sample)."""

    def __init__(self, node: Any, host: str, port: int, topics: Sequence[str],
                 max_rate_hz: float, use_sim_time: bool) -> None:
        self.context = foxglove.Context()
        self.channels: dict[str, foxglove.Channel] = {}
        #: samples handed to the SDK per topic (what it then sends depends on the subscribers)
        self.forwarded: dict[str, int] = {}
        self.every_sample = max_rate_hz == 0
        super().__init__(node, topics, on_demand=True, poll_period_s=(
            EVERY_SAMPLE_POLL_S if self.every_sample else 1.0 / max_rate_hz),
            read_taps=not self.every_sample and max_rate_hz <= TAP_RATE_HZ,
            newest_only=not self.every_sample)
        self.server = foxglove.start_server(
            name="stillframe monitor", host=host, port=port, context=self.context,
            server_listener=self, capabilities=[foxglove.Capability.Time],
            supported_encodings=[MESSAGE_ENCODING], message_backlog_size=CLIENT_BACKLOG)
        #: the newest /clock [ns] (sim time only)
        self.sim_time_ns: int | None = None
        self.use_sim_time = use_sim_time
        self._newest_clock: bytes | None = None
        if use_sim_time:
            if self.topics:
                self.topics.add(ClockPublisher.TOPIC)
            self.want(ClockPublisher.TOPIC, True)

    def on_subscribe(self, client: Any, channel: Any) -> None:
        """A client subscribed to a channel (the SDK's server thread)."""
        self.want(channel.topic, True)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        """A client unsubscribed from a channel or disconnected."""
        self.want(channel.topic, False)

    def request(self, offers: list[QoSProfile]) -> QoSProfile:
        """A live viewer's QoS for the ``offers``
        (:func:`~stillframe.middleware.qos.viewer_request`: best effort), one sample deep unless
        every sample is asked for."""
        request = viewer_request(offers)
        return request if self.every_sample else request.with_depth(1)

    def on_new_topic(self, topic: str, msgtype: str, offers: list[QoSProfile]) -> RawCallback:
        """Open a Foxglove channel for ``topic`` (its ``ros2msg`` schema, CDR encoding) and return
        the callback that logs each sample on it unchanged, stamped with its receive time or the
        newest sim time; with ``use_sim_time`` the ``/clock`` callback also keeps the newest clock
        for :meth:`poll`."""
        channel = foxglove.Channel(topic, schema=ros2msg_schema(msgtype),
                                   message_encoding=MESSAGE_ENCODING, context=self.context)
        self.channels[topic] = channel
        self.forwarded[topic] = 0

        def forward(data: bytes, info: MessageInfo) -> None:
            channel.log(data, log_time=info.received_timestamp if self.sim_time_ns is None
                        else self.sim_time_ns)
            self.forwarded[topic] += 1

        if topic != ClockPublisher.TOPIC or not self.use_sim_time:
            return forward

        def forward_clock(data: bytes, info: MessageInfo) -> None:
            self._newest_clock = data
            forward(data, info)

        return forward_clock

    def poll(self) -> None:
        """Forward what waits, then broadcast the newest /clock (with sim time)."""
        super().poll()
        if self._newest_clock is not None:
            clock = messages.deserialize(self._newest_clock, ClockPublisher.TYPE).clock
            self._newest_clock = None
            self.sim_time_ns = messages.stamp_ns(clock)
            self.server.broadcast_time(self.sim_time_ns)
