"""``stillframe bench transport``: ping-pong RTT between two processes, node API vs raw Cyclone.

A ping process sends ``sensor_msgs/msg/Imu`` at ``--rate`` Hz (QoS sensor_data) for
``--duration`` s; a peer process decodes each ping and sends it back as a pong. Round-trip
times are measured on the ping side's monotonic clock (the ping's ``header.stamp``). The same
run measures three variants, both ends alike:

- ``raw``: Cyclone's C path only, the floor the node API cannot beat: the peer takes the
  serialized sample and writes the same bytes back; the ping side patches the stamp into
  pre-serialized bytes (no Python (de)serialization at all);
- ``typed``: ``cyclonedds``' own Python API (typed reader and writer of the generated struct,
  its pure-Python serializer) - what a hand-written cyclonedds program gets;
- ``api``: the node API (``rosbags`` CDR, callbacks, the executor).

Printed: RTT p50 / p99 / max, lost pings, and the API/raw ratios (target: p99 <= 1.5).
"""

from __future__ import annotations

import argparse
import os
import struct
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from cyclonedds.core import InstanceState, SampleState, ViewState

from cyclonedds._clayer import ddspy_take, ddspy_write  # isort: skip
from stillframe import messages
from stillframe.commands.common import add_json_argument, emit_json, format_table
from stillframe.errors import InputError
from stillframe.middleware import api
from stillframe.middleware.dds_backend import pad4

PING, PONG = "/stillframe_bench/ping", "/stillframe_bench/pong"
IMU = "sensor_msgs/msg/Imu"
ANY_SAMPLE = SampleState.Any | ViewState.Any | InstanceState.Any
STAMP = struct.Struct("<iI")  # header.stamp right after the 4-byte CDR encapsulation header
VARIANTS = ("raw", "typed", "api")
DRAIN_S = 0.5
READY_TIMEOUT_S = 20.0
REPO_ROOT = Path(__file__).resolve().parents[2]


def register(benches: argparse._SubParsersAction) -> None:
    parser = benches.add_parser(
        "transport", help="ping-pong RTT between two processes: node API vs raw Cyclone DDS"
    )
    parser.add_argument("--duration", type=float, default=10.0, metavar="S",
                        help="seconds of pinging per variant (default 10)")
    parser.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                        help="pings per second (default 1000)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


# -- the raw Cyclone ends ---------------------------------------------------------------------
class RawEnd:
    """Plain cyclonedds: one participant, a writer on ``out``, a reader on ``inp``, a waitset."""

    def __init__(self, out: str, inp: str) -> None:
        from cyclonedds.core import ReadCondition, WaitSet
        from cyclonedds.domain import Domain, DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from stillframe.middleware import dds_backend, dds_types
        from stillframe.middleware.qos import SENSOR_DATA

        domain = dds_backend.domain_id()
        config = None if os.environ.get("CYCLONEDDS_URI") else dds_backend.CONFIG_FILE.read_text()
        self.domain = Domain(domain, config) if config else None
        self.participant = DomainParticipant(domain)
        self.struct = dds_types.idl_struct(IMU)
        qos = dds_backend.dds_qos(SENSOR_DATA)
        self.writer = DataWriter(
            self.participant, Topic(self.participant, "rt" + out, self.struct), qos)
        self.reader = DataReader(
            self.participant, Topic(self.participant, "rt" + inp, self.struct), qos)
        self.waitset = WaitSet(self.participant)
        self.waitset.attach(ReadCondition(self.reader, ANY_SAMPLE))

    def ready(self) -> bool:
        return bool(self.writer.get_matched_subscriptions()) and bool(
            self.reader.get_matched_publications())


def raw_peer() -> None:
    end = RawEnd(PONG, PING)
    while api.ok():
        end.waitset.wait(100_000_000)
        for data, _info in ddspy_take(end.reader._ref, ANY_SAMPLE, 64):
            ddspy_write(end.writer._ref, data)


def raw_ping(rate: float, duration: float) -> tuple[int, list[int]]:
    end = RawEnd(PING, PONG)
    _wait(end.ready)
    ping = bytearray(pad4(messages.serialize(messages.new(IMU))))
    rtts: list[int] = []

    def send(k: int) -> None:
        STAMP.pack_into(ping, 4, *divmod(time.monotonic_ns(), 1_000_000_000))
        ddspy_write(end.writer._ref, bytes(ping))

    def receive(timeout_ns: int) -> None:
        end.waitset.wait(max(timeout_ns, 0))
        now = time.monotonic_ns()
        for data, _info in ddspy_take(end.reader._ref, ANY_SAMPLE, 64):
            sec, nanosec = STAMP.unpack_from(data, 4)
            rtts.append(now - (sec * 1_000_000_000 + nanosec))

    return _drive(rate, duration, send, receive), rtts


def typed_peer() -> None:
    end = RawEnd(PONG, PING)
    while api.ok():
        end.waitset.wait(100_000_000)
        for sample in end.reader.take(N=64):
            end.writer.write(sample)


def typed_ping(rate: float, duration: float) -> tuple[int, list[int]]:
    end = RawEnd(PING, PONG)
    _wait(end.ready)
    idl_template = end.struct.deserialize(messages.serialize(messages.new(IMU)))
    rtts: list[int] = []

    def send(k: int) -> None:
        idl_template.header.stamp.sec, idl_template.header.stamp.nanosec = divmod(
            time.monotonic_ns(), 1_000_000_000)
        idl_template.header.frame_id = str(k)
        end.writer.write(idl_template)

    def receive(timeout_ns: int) -> None:
        end.waitset.wait(max(timeout_ns, 0))
        now = time.monotonic_ns()
        for pong in end.reader.take(N=64):
            rtts.append(now - (pong.header.stamp.sec * 1_000_000_000 + pong.header.stamp.nanosec))

    return _drive(rate, duration, send, receive), rtts


# -- the node API ends ------------------------------------------------------------------------
def api_peer() -> None:
    node = api.create_node("bench_transport_peer", argv=["bench"])
    pong = node.create_publisher(IMU, PONG, "sensor_data")
    node.create_subscription(IMU, PING, pong.publish, "sensor_data")
    api.spin(node)
    node.destroy_node()


def api_ping(rate: float, duration: float) -> tuple[int, list[int]]:
    node = api.create_node("bench_transport_ping", argv=["bench"])
    rtts: list[int] = []

    def on_pong(msg: object) -> None:
        rtts.append(time.monotonic_ns() - messages.stamp_ns(msg.header.stamp))

    ping = node.create_publisher(IMU, PING, "sensor_data")
    sub = node.create_subscription(IMU, PONG, on_pong, "sensor_data")
    _wait(lambda: ping.get_subscription_count() > 0 and sub.get_publisher_count() > 0,
          lambda: node.spin_once(0.01))
    msg = messages.new(IMU)

    def send(k: int) -> None:
        msg.header.stamp = messages.time_msg(time.monotonic_ns())
        msg.header.frame_id = str(k)
        ping.publish(msg)

    sent = _drive(rate, duration, send, lambda timeout_ns: node.spin_once(timeout_ns * 1e-9))
    node.destroy_node()
    return sent, rtts


# -- shared driver ----------------------------------------------------------------------------
def _wait(ready: Callable[[], bool], step: Callable[[], None] = lambda: time.sleep(0.01)) -> None:
    deadline = time.monotonic() + READY_TIMEOUT_S
    while not ready():
        if time.monotonic() > deadline:
            raise InputError(f"bench transport: no peer connected within {READY_TIMEOUT_S} s")
        step()


def _drive(rate: float, duration: float, send: Callable[[int], None],
           receive: Callable[[int], None]) -> int:
    """Send at ``rate`` for ``duration``, receiving in between; drain; the number sent."""
    period = round(1e9 / rate)
    start = time.monotonic_ns()
    end = start + round(duration * 1e9)
    k = 0
    while True:
        now = time.monotonic_ns()
        due = start + k * period
        if now >= end:
            break
        if now >= due:
            send(k)
            k += 1
            continue
        receive(due - now)
    drain_end = time.monotonic_ns() + round(DRAIN_S * 1e9)
    while time.monotonic_ns() < drain_end:
        receive(10_000_000)
    return k


def _measure(variant: str, rate: float, duration: float) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    peer = subprocess.Popen(
        [sys.executable, "-m", "stillframe.commands.bench_transport", "--peer", variant],
        env=env, stderr=subprocess.DEVNULL,
    )
    try:
        ping = {"raw": raw_ping, "typed": typed_ping, "api": api_ping}[variant]
        sent, rtts = ping(rate, duration)
    finally:
        peer.terminate()
        peer.wait(timeout=30)
    us = np.asarray(rtts, dtype=float) * 1e-3
    return {
        "sent": sent, "received": len(rtts), "lost": sent - len(rtts),
        "p50_us": float(np.percentile(us, 50)) if len(us) else float("nan"),
        "p99_us": float(np.percentile(us, 99)) if len(us) else float("nan"),
        "max_us": float(us.max()) if len(us) else float("nan"),
    }


def run(args: argparse.Namespace) -> int:
    if not args.duration > 0 or not args.rate > 0:
        raise InputError("bench transport: --duration and --rate must be > 0")
    results = {}
    for variant in VARIANTS:
        print(f"bench transport: {variant}, {args.duration:g} s at {args.rate:g} Hz ...",
              file=sys.stderr, flush=True)
        results[variant] = _measure(variant, args.rate, args.duration)
    ratios = {key: results["api"][key] / results["raw"][key] for key in ("p50_us", "p99_us")}
    document = {"message": IMU, "qos": "sensor_data", "rate_hz": args.rate,
                "duration_s": args.duration, "backend": api.backend_name(),
                **results, "api_over_raw": ratios}
    if args.json:
        emit_json(document)
        return 0
    rows = [[name, r["sent"], r["lost"], r["p50_us"], r["p99_us"], r["max_us"]]
            for name, r in results.items()]
    print(format_table(["variant", "sent", "lost", "p50 [us]", "p99 [us]", "max [us]"], rows))
    print(f"API / raw: p50 x{ratios['p50_us']:.2f}, p99 x{ratios['p99_us']:.2f} "
          "(target: p99 <= 1.5)")
    return 0


if __name__ == "__main__":
    api.install_signal_handlers()
    {"raw": raw_peer, "typed": typed_peer, "api": api_peer}[sys.argv[-1]]()
