"""The protocol client against a real ``foxglove-sdk`` server whose channels appear while the
client is connected, as the bridge's topics do during a launch."""

from __future__ import annotations

import asyncio
import threading
import time

import foxglove

from stillframe.monitor.foxglove_bridge import ros2msg_schema
from stillframe.monitor.foxglove_client import Capture, capture
from tests.support.waits import HANG_S

CHANNELS = 300


def test_every_channel_advertised_while_connected_delivers() -> None:
    """Channels created 2 ms apart while the client subscribes to each as it is advertised.
    The SDK sometimes refuses such a subscription as for an unknown channel (it queues the
    advertisement before recording it; the count is in the message); the client subscribes
    again, so every channel's messages arrive."""
    context = foxglove.Context()
    server = foxglove.start_server(host="127.0.0.1", port=0, context=context)
    channels: list[foxglove.Channel] = []
    connected, created = threading.Event(), threading.Event()

    def create_and_log() -> None:
        connected.wait(HANG_S)
        schema = ros2msg_schema("std_msgs/msg/UInt32")
        for i in range(CHANNELS):
            channels.append(foxglove.Channel(f"/c{i}", schema=schema, message_encoding="cdr",
                                             context=context))
            time.sleep(0.002)
        created.set()
        for _ in range(20):  # after every subscription has settled
            time.sleep(0.05)
            for channel in channels:
                channel.log(b"\x00\x01\x00\x00\x07\x00\x00\x00")

    async def client() -> Capture:
        seen, until = Capture(), asyncio.Event()
        task = asyncio.create_task(capture(f"ws://127.0.0.1:{server.port}", None, until, seen,
                                           decode=False))
        while not seen.server_info:
            await asyncio.sleep(0.01)
        connected.set()
        await asyncio.to_thread(logger.join)
        await asyncio.sleep(0.5)
        until.set()
        await task
        return seen

    logger = threading.Thread(target=create_and_log)
    logger.start()
    try:
        seen = asyncio.run(client())
    finally:
        server.stop()
    assert created.is_set()
    missing = sorted(set(f"/c{i}" for i in range(CHANNELS)) - set(seen.messages))
    assert not missing, f"{len(missing)} channels silent, {seen.resubscribed} resubscribed"
    assert all(len(sizes) >= 10 and set(sizes) == {8} for sizes in seen.messages.values())
