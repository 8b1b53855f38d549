"""Ping-pong RTT between two processes, node API vs raw Cyclone (``stillframe bench transport``).

The ping process (this one) sends ``sensor_msgs/msg/Imu`` at ``--rate`` Hz (QoS sensor_data);
a peer process decodes each ping and sends it back as a pong. Round-trip times are measured on
the ping side's monotonic clock (the stamp carried in ``header.stamp``). Three variants, both
ends alike, each with its own peer process and topics:

- ``raw``: Cyclone's C path only, the floor the node API cannot beat: the peer takes the
  serialized sample and writes the same bytes back; the ping side patches the stamp into
  pre-serialized bytes (no Python (de)serialization at all);
- ``typed``: ``cyclonedds``' own Python API (typed reader and writer of the generated struct,
  its pure-Python serializer) - what a hand-written cyclonedds program gets;
- ``api``: the node API on each backend (``rosbags`` CDR, callbacks, the executor);
- ``dds_raw``: the node API as the loop's nodes use it on the dds backend: a raw subscription
  and a preallocated CDR buffer patched and written as it is (the fixed-layout codecs' path,
  no ``rosbags``).

The variants take turns in one-second blocks until each has pinged ``--duration`` seconds, so
that the load of a shared machine affects them alike. Printed: RTT p50 / p99 / max, lost
pings, and the API/raw ratios (target: p99 <= 1.5).
"""

from __future__ import annotations

import functools
import math
import os
import struct
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from cyclonedds.core import ReadCondition, WaitSet
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT
from stillframe.middleware import api, dds_backend, dds_types, discovery
from stillframe.middleware.cyclone_raw import ANY_SAMPLES, pad4, take_raw, write_raw
from stillframe.middleware.qos import SENSOR_DATA

IMU = "sensor_msgs/msg/Imu"
#: raw and typed Cyclone, then the node API on each backend installed here
VARIANTS = ("raw", "typed", "dds_raw",
            *(b for b in api.BACKENDS if b == "dds" or api.has_rclpy()))
STAMP = struct.Struct("<iI")  # header.stamp right after the 4-byte CDR encapsulation header
BLOCK_S = 1.0
BLOCK_DRAIN_NS = 20_000_000
FINAL_DRAIN_S = 0.5
READY_TIMEOUT_S = 30.0
#: back to back: a pong not in after this long [ns] is lost, and the next ping goes
LOST_NS = 10_000_000


def topics(variant: str) -> tuple[str, str]:
    """The ping and pong topics of ``variant``."""
    return f"/stillframe_bench/{variant}/ping", f"/stillframe_bench/{variant}/pong"


def now_stamp() -> tuple[int, int]:
    """``(sec, nanosec)`` of the monotonic clock, as a ``header.stamp`` carries it."""
    return divmod(time.monotonic_ns(), 1_000_000_000)


class CycloneEnd:
    """Plain cyclonedds: a participant, a writer on ``out``, a reader on ``inp``, a waitset."""

    def __init__(self, out: str, inp: str, own_domain: bool) -> None:
        domain = discovery.domain_id()
        config = discovery.cyclone_config()
        self.domain = Domain(domain, config) if own_domain and config else None
        self.participant = DomainParticipant(domain)
        self.struct = dds_types.idl_struct(IMU)
        qos = dds_backend.dds_qos(SENSOR_DATA)
        self.writer = DataWriter(
            self.participant, Topic(self.participant, dds_types.dds_topic(out), self.struct), qos)
        self.reader = DataReader(
            self.participant, Topic(self.participant, dds_types.dds_topic(inp), self.struct), qos)
        self.waitset = WaitSet(self.participant)
        self.waitset.attach(ReadCondition(self.reader, ANY_SAMPLES))

    def ready(self) -> bool:
        """Whether both ends are matched: the writer with a reader and the reader with a writer."""
        return bool(self.writer.get_matched_subscriptions()) and bool(
            self.reader.get_matched_publications())


# -- the pinging side ---------------------------------------------------------------------------
class RawPinger:
    """Pings through Cyclone's C path: pre-serialized bytes with the stamp patched in."""

    def __init__(self) -> None:
        self.end = CycloneEnd(*topics("raw"), own_domain=False)
        self.ping = bytearray(pad4(messages.serialize(messages.new(IMU))))
        self.rtts: list[int] = []
        self.ready = self.end.ready

    def send(self) -> None:
        """Write one ping stamped now."""
        STAMP.pack_into(self.ping, 4, *now_stamp())
        write_raw(self.end.writer, bytes(self.ping))

    def receive(self, timeout_ns: int) -> None:
        """Wait at most ``timeout_ns`` and record the round-trip time of every pong taken [ns]."""
        self.end.waitset.wait(timeout_ns)
        now = time.monotonic_ns()
        for data, _info in take_raw(self.end.reader, 64):
            sec, nanosec = STAMP.unpack_from(data, 4)
            self.rtts.append(now - (sec * 1_000_000_000 + nanosec))


class TypedPinger:
    """Pings through ``cyclonedds``' own Python API: a typed writer and reader of the generated
    struct."""

    def __init__(self) -> None:
        self.end = CycloneEnd(*topics("typed"), own_domain=False)
        self.ping = self.end.struct.deserialize(messages.serialize(messages.new(IMU)))
        self.rtts: list[int] = []
        self.ready = self.end.ready

    def send(self) -> None:
        """Write one ping stamped now."""
        self.ping.header.stamp.sec, self.ping.header.stamp.nanosec = now_stamp()
        self.end.writer.write(self.ping)

    def receive(self, timeout_ns: int) -> None:
        """Wait at most ``timeout_ns`` and record the round-trip time of every pong taken [ns]."""
        self.end.waitset.wait(timeout_ns)
        now = time.monotonic_ns()
        for pong in self.end.reader.take(N=64):
            self.rtts.append(now - (pong.header.stamp.sec * 1_000_000_000
                                    + pong.header.stamp.nanosec))


class ApiPinger:
    """The node API on one backend (the variant's name), or raw bytes through it (``dds_raw``)."""

    def __init__(self, node: api.Node, variant: str) -> None:
        self.node = node
        self.rtts: list[int] = []
        ping, pong = topics(variant)
        self.pub = node.create_publisher(IMU, ping, "sensor_data")
        self.raw = variant == "dds_raw"
        self.sub = node.create_subscription(IMU, pong, self.on_raw if self.raw else self.on_pong,
                                            "sensor_data", raw=self.raw)
        self.ping = messages.new(IMU)
        self.cdr = bytearray(pad4(messages.serialize(self.ping)))

    def ready(self) -> bool:
        """Whether the ping publisher and the pong subscription are both matched."""
        return self.pub.get_subscription_count() > 0 and self.sub.get_publisher_count() > 0

    def on_pong(self, msg: Any) -> None:
        """Record the round-trip time of a decoded pong [ns]."""
        self.rtts.append(time.monotonic_ns() - messages.stamp_ns(msg.header.stamp))

    def on_raw(self, cdr: bytes, _info: Any) -> None:
        """Record the round-trip time of a raw pong, its stamp read from the CDR bytes [ns]."""
        sec, nanosec = STAMP.unpack_from(cdr, 4)
        self.rtts.append(time.monotonic_ns() - (sec * 1_000_000_000 + nanosec))

    def send(self) -> None:
        """Publish one ping stamped now: the patched CDR buffer (``dds_raw``) or the message."""
        if self.raw:
            STAMP.pack_into(self.cdr, 4, *now_stamp())
            self.pub.publish(self.cdr)
        else:
            self.ping.header.stamp = messages.time_msg(time.monotonic_ns())
            self.pub.publish(self.ping)

    def receive(self, timeout_ns: int) -> None:
        """Spin the node at most ``timeout_ns``; the pong callbacks record the round trips."""
        self.node.spin_once(timeout_ns * 1e-9)


def drive(pinger: Any, rate: float, seconds: float) -> int:
    """Ping at ``rate`` for ``seconds``, receiving in between (``rate`` 0: back to back, the
    next ping when the pong is in, as a lock-step loop sends; a ping lost is sent again after
    :data:`LOST_NS`); the number of pings sent."""
    period = round(1e9 / rate) if rate else 0
    start = time.monotonic_ns()
    end = start + round(seconds * 1e9)
    sent, answered, sent_at = 0, len(pinger.rtts), 0
    while (now := time.monotonic_ns()) < end:
        if period:
            due = start + sent * period
        else:
            due = now if (len(pinger.rtts) - answered >= sent
                          or now - sent_at >= LOST_NS) else now + LOST_NS
        if now >= due:
            pinger.send()
            sent += 1
            sent_at = now
        else:
            pinger.receive(due - now)
    drain_end = time.monotonic_ns() + BLOCK_DRAIN_NS
    while (now := time.monotonic_ns()) < drain_end:
        pinger.receive(drain_end - now)
    return sent


# -- the echoing side (``python -m stillframe.app.bench.pingpong --peer VARIANT``) ---------
def raw_peer() -> None:
    """Echo every ping's bytes back as they came, on Cyclone's C path, until shutdown."""
    ping, pong = topics("raw")
    end = CycloneEnd(pong, ping, own_domain=True)
    while api.ok():
        end.waitset.wait(100_000_000)
        for data, _info in take_raw(end.reader, 64):
            write_raw(end.writer, data)


def typed_peer() -> None:
    """Echo every ping back through ``cyclonedds``' typed reader and writer, until shutdown."""
    ping, pong = topics("typed")
    end = CycloneEnd(pong, ping, own_domain=True)
    while api.ok():
        end.waitset.wait(100_000_000)
        for sample in end.reader.take(N=64):
            end.writer.write(sample)


def api_peer(variant: str) -> None:
    """Echo through the node API: decoded messages, or the bytes as they came (``dds_raw``)."""
    ping, pong = topics(variant)
    raw = variant == "dds_raw"
    node = api.create_node(f"bench_transport_peer_{variant}", argv=["bench"],
                           backend="dds" if raw else variant)
    publisher = node.create_publisher(IMU, pong, "sensor_data")
    node.create_subscription(IMU, ping, (lambda cdr, _info: publisher.publish(cdr)) if raw
                             else publisher.publish, "sensor_data", raw=raw)
    api.spin(node)
    node.destroy_node()


PEERS: dict[str, Callable[[], None]] = {
    "raw": raw_peer, "typed": typed_peer,
    **{variant: functools.partial(api_peer, variant) for variant in (*api.BACKENDS, "dds_raw")},
}


# -- the command ----------------------------------------------------------------------------
def _wait_ready(node: api.Node, pingers: dict[str, Any]) -> None:
    deadline = time.monotonic() + READY_TIMEOUT_S
    while not all(p.ready() for p in pingers.values()):
        if time.monotonic() > deadline or not api.ok():
            missing = [name for name, p in pingers.items() if not p.ready()]
            raise InputError(f"bench transport: peer(s) {', '.join(missing)} did not connect "
                             f"within {READY_TIMEOUT_S:g} s")
        node.spin_once(0.01)


def _summary(sent: int, rtts: list[int]) -> dict[str, float]:
    us = np.asarray(rtts, dtype=float) * 1e-3
    stat = (lambda f: float(f(us))) if len(us) else (lambda f: float("nan"))
    return {
        "sent": sent, "received": len(rtts), "lost": sent - len(rtts),
        "p50_us": stat(lambda a: np.percentile(a, 50)),
        "p99_us": stat(lambda a: np.percentile(a, 99)),
        "max_us": stat(np.max),
    }


def measure(rate: float, duration: float,
            variants: Sequence[str] = VARIANTS) -> dict[str, dict[str, float]]:
    """Run ``variants`` interleaved at ``rate`` (0: back to back, :func:`drive`); per variant the
    figures of :func:`_summary`."""
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    peers = [
        subprocess.Popen([sys.executable, "-m", "stillframe.app.bench.pingpong",
                          "--peer", variant], env=env, stderr=subprocess.DEVNULL)
        for variant in variants
    ]
    nodes = {v: api.create_node(f"bench_transport_ping_{v}", argv=["bench"],
                                backend="dds" if v == "dds_raw" else v)
             for v in (*variants, "dds") if v in (*api.BACKENDS, "dds_raw")}
    node = nodes["dds"]
    try:
        cyclone = {"raw": RawPinger, "typed": TypedPinger}
        pingers = {v: cyclone[v]() if v in cyclone else ApiPinger(nodes[v], v) for v in variants}
        _wait_ready(node, pingers)
        sent = dict.fromkeys(variants, 0)
        blocks = math.ceil(duration / BLOCK_S)
        for block in range(blocks):
            seconds = min(BLOCK_S, duration - block * BLOCK_S)
            for variant in variants:
                if not api.ok():
                    raise KeyboardInterrupt
                sent[variant] += drive(pingers[variant], rate, seconds)
            print(f"bench transport: {min((block + 1) * BLOCK_S, duration):g} of {duration:g} s",
                  file=sys.stderr, flush=True)
        drain_end = time.monotonic() + FINAL_DRAIN_S
        while time.monotonic() < drain_end:
            for pinger in pingers.values():
                pinger.receive(5_000_000)
        return {v: _summary(sent[v], pingers[v].rtts) for v in variants}
    finally:
        for each in nodes.values():
            each.destroy_node()
        for peer in peers:
            peer.terminate()
        for peer in peers:
            peer.wait(timeout=30)


if __name__ == "__main__":
    api.install_signal_handlers()
    PEERS[sys.argv[-1]]()
