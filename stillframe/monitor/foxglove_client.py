"""A minimal ``foxglove.websocket.v1`` client (for the tests and ``bench monitor``), as
Foxglove's spec defines the protocol: JSON ``serverInfo``/``advertise``, ``subscribe``; binary
message data (opcode 1: subscription id u32, receive time u64, payload) and time (opcode 2: u64
ns), little-endian. ``foxglove-sdk``'s server calls it ``foxglove.sdk.v1`` (the same protocol
under its new name) and accepts only that name, so the client offers both.

Messages are decoded with the schema the server advertised only: its ``ros2msg`` text is parsed
into an empty ``rosbags`` typestore, so nothing of our own message definitions is used.

A subscription sent right after an ``advertise`` can be refused with the status "Unknown channel
ID": ``foxglove-sdk`` (0.30) queues the advertisement to the client before it records the channel
as advertised to that client, so a fast client's subscribe can be handled in between (see
docs/monitor.md). The client then subscribes again, since the server did advertise the channel."""

from __future__ import annotations

import asyncio
import json
import re
import struct
from dataclasses import dataclass, field
from typing import Any

import websockets
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

#: the new name first: the server picks the first it knows
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA, TIME = 1, 2
#: the status the server sends for a subscription to a channel it does not (yet) know
UNKNOWN_CHANNEL = re.compile(r"Unknown channel ID: (\d+)")


@dataclass
class Capture:
    """What a client saw: server info, advertised channels by topic, decoded messages of the
    subscribed topics and the server times broadcast."""

    subprotocol: str = ""
    server_info: dict[str, Any] = field(default_factory=dict)
    channels: dict[str, dict[str, Any]] = field(default_factory=dict)
    messages: dict[str, list[Any]] = field(default_factory=dict)
    times: list[int] = field(default_factory=list)
    #: subscriptions sent again after the server refused them as for an unknown channel
    resubscribed: int = 0


def decoder(channel: dict[str, Any]) -> Any:
    """A function CDR bytes -> message, from the channel's advertised schema alone."""
    assert channel["schemaEncoding"] == "ros2msg" and channel["encoding"] == "cdr", channel
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(channel["schema"], channel["schemaName"]))
    return lambda data: store.deserialize_cdr(data, channel["schemaName"])


def refused_channel(message: dict[str, Any]) -> int | None:
    """The channel id of an "Unknown channel ID" status, else None."""
    if message["op"] != "status":
        return None
    refused = UNKNOWN_CHANNEL.fullmatch(message["message"])
    return None if refused is None else int(refused[1])


async def capture(url: str, topics: list[str] | None, until: asyncio.Event,
                  out: Capture, decode: bool = True) -> None:
    """Subscribe to ``topics`` (None: every topic) as they are advertised and decode what
    arrives (or, without ``decode``, keep its size) until ``until`` is set or the server closes."""
    subscribed: dict[int, tuple[str, Any]] = {}
    subscription_of: dict[int, int] = {}  # channel id -> subscription id

    async def subscribe(channel_id: int) -> None:
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": subscription_of[channel_id], "channelId": channel_id}]}))

    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        out.subprotocol = ws.subprotocol or ""
        while not until.is_set():
            try:
                frame = await asyncio.wait_for(ws.recv(), 0.2)
            except TimeoutError:
                continue
            except websockets.ConnectionClosed:
                return
            if isinstance(frame, str):
                message = json.loads(frame)
                if message["op"] == "serverInfo":
                    out.server_info = message
                elif message["op"] == "advertise":
                    for channel in message["channels"]:
                        out.channels[channel["topic"]] = channel
                        if topics is None or channel["topic"] in topics:
                            sub_id = len(subscribed) + 1
                            subscribed[sub_id] = (channel["topic"], decoder(channel))
                            subscription_of[channel["id"]] = sub_id
                            await subscribe(channel["id"])
                elif (refused := refused_channel(message)) is not None and (
                        refused in subscription_of):
                    out.resubscribed += 1
                    await subscribe(refused)
            elif frame[0] == MESSAGE_DATA:
                sub_id, _receive_ns = struct.unpack_from("<IQ", frame, 1)
                topic, decoded = subscribed[sub_id]
                payload = frame[13:]
                out.messages.setdefault(topic, []).append(
                    decoded(payload) if decode else len(payload))
            elif frame[0] == TIME:
                out.times.append(struct.unpack_from("<Q", frame, 1)[0])


async def stall(url: str, topic: str, until: asyncio.Event, at_least: int = 1) -> int:
    """A slow client: once ``topic`` and at least ``at_least`` channels are advertised,
    subscribes to every channel advertised so far, then stops reading until ``until``; the
    number of channels it subscribed to."""
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None,
                                  max_queue=1) as ws:
        channels: dict[str, int] = {}
        while topic not in channels or len(channels) < at_least:
            frame = await ws.recv()
            if isinstance(frame, bytes):
                continue  # time broadcasts may come before the advertisement
            message = json.loads(frame)
            if message["op"] == "advertise":
                channels.update({c["topic"]: c["id"] for c in message["channels"]})
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i + 1, "channelId": c} for i, c in enumerate(channels.values())]}))
        ws.transport.pause_reading()  # the kernel's buffers fill, then the server's queue
        while not until.is_set():
            await asyncio.sleep(0.1)
        return len(channels)


async def churn(url: str, until: asyncio.Event) -> int:
    """Clients connecting, reading the first frames and disconnecting, again and again; how
    many connected before the monitor stopped."""
    count = 0
    while not until.is_set():
        try:
            async with websockets.connect(url, subprotocols=SUBPROTOCOLS) as ws:
                await ws.recv()
                count += 1
        except (OSError, websockets.WebSocketException):
            return count  # the monitor stopped at the end of the launch
        await asyncio.sleep(0.05)
    return count
