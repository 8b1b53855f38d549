"""A hostile writer (issue 11, item 5), run as ``python tests/support/hostile_writer.py BACKEND
RATE SECONDS TOPICS [AFTER_CLOCK_S [READERS]]``. TOPICS ``own``: the LQG loop's own sensor
topics (``floor1/imu``, ``pendulum/joint_states``, ``excitation/wrench``); ``unused``: topics it
does not read (``floor3/force_cmd``, a command topic it does not drive, ``floor3/load_cell``,
``unused/imu``); ``control``: the loop's control path and time (``state_estimate``, ``/clock``,
``pendulum/torque_cmd``), which its nodes take from the loop's writers only. Once the loop's
readers have matched (and ``/clock`` has reached AFTER_CLOCK_S): ``RATE`` messages/s in all,
stamped 0, -5 s and +2e9 s (on ``control`` also, every fourth, the loop's newest ``/clock``:
a stamp the loop would take), with an empty ``frame_id`` and every 5000th a 1 MB one,
JointState arrays of mismatched lengths, and about every 100th sample garbage or truncated CDR
(empty, a bare header, 48 random bytes, half a message) under the topic's type name.
``BACKEND``: ``rclpy`` (a real rclpy peer on Fast DDS) or ``dds`` (a Cyclone DDS writer of
ours). Prints ``ready``, writes for ``SECONDS`` (or until SIGTERM), then prints (last) ``sent GOOD
GARBAGE_SENT GARBAGE_REFUSED RATE``.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from typing import Any

import numpy as np

TYPES = {"floor1/imu": "sensor_msgs/msg/Imu",
         "pendulum/joint_states": "sensor_msgs/msg/JointState",
         "excitation/wrench": "geometry_msgs/msg/WrenchStamped",
         "floor3/force_cmd": "geometry_msgs/msg/WrenchStamped",
         "floor3/load_cell": "geometry_msgs/msg/WrenchStamped",
         "unused/imu": "sensor_msgs/msg/Imu",
         "state_estimate": "sensor_msgs/msg/JointState",
         "/clock": "rosgraph_msgs/msg/Clock",
         "pendulum/torque_cmd": "geometry_msgs/msg/WrenchStamped"}
#: topics the LQG loop has no reader of (not waited for)
UNREAD = ("floor3/load_cell", "unused/imu")
TOPICS = {"own": ("floor1/imu", "pendulum/joint_states", "excitation/wrench"),
          "unused": ("floor3/force_cmd", "floor3/load_cell", "unused/imu"),
          "control": ("state_estimate", "/clock", "pendulum/torque_cmd")}
STAMPS = [(0, 0), (-5, 0), (2_000_000_000, 0)]
BIG = "x" * 1_000_000
#: the stamps above in ns: a ``/clock`` at one of them is a hostile writer's, not the loop's
HOSTILE_NS = {sec * 1_000_000_000 + nsec for sec, nsec in STAMPS}


def follow_loop_clock(node: Any) -> list[int]:
    """Subscribe ``/clock`` on ``node``; the loop's time is kept in the list's element (a
    reader deep enough for a flooded ``/clock``, the hostile writers' stamps skipped)."""
    from stillframe.middleware.qos import QoSProfile, Reliability

    clock = [0]

    def on_clock(msg: Any) -> None:
        ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        if ns not in HOSTILE_NS:
            clock[0] = ns

    node.create_subscription("rosgraph_msgs/msg/Clock", "/clock", on_clock,
                             QoSProfile(depth=1000, reliability=Reliability.BEST_EFFORT))
    return clock


def hostile(messages: Any, topic: str, i: int, clock_ns: int) -> Any:
    """The ``i``-th hostile message on ``topic`` while the loop's ``/clock`` is ``clock_ns``."""
    m = messages.new(TYPES[topic])
    stamps = [*STAMPS, divmod(clock_ns, 1_000_000_000)] if topic in TOPICS["control"] else STAMPS
    stamp = stamps[i % len(stamps)]
    if topic == "/clock":
        m.clock.sec, m.clock.nanosec = stamp
        return m
    m.header.stamp.sec, m.header.stamp.nanosec = stamp
    m.header.frame_id = BIG if i % 5000 == 0 else ""
    if TYPES[topic].endswith("JointState"):
        m.name, m.position, m.effort = ["pendulum", "x"], np.array([0.3]), np.array([1.0, 2, 3])
    return m


def main() -> None:
    os.environ["STILLFRAME_RMW"] = sys.argv[1]
    rate, seconds = float(sys.argv[2]), float(sys.argv[3])
    from stillframe.contract import messages
    from stillframe.middleware import api
    from stillframe.middleware.qos import Durability, QoSProfile, Reliability

    # reliable and transient-local: matches the loop's lock-step readers and every other one
    qos = QoSProfile(depth=5, reliability=Reliability.RELIABLE,
                     durability=Durability.TRANSIENT_LOCAL)

    node = api.create_node(f"hostile_{sys.argv[1]}", namespace="/frame", argv=["w"])
    pubs = {t: node.create_publisher(TYPES[t], t, qos) for t in TOPICS[sys.argv[4]]}
    whole = {t: messages.serialize(hostile(messages, t, 1, 0)) for t in TYPES}
    garbage = [b"", b"\x00\x01\x00\x00",
               b"\x00\x01\x00\x00" + np.random.default_rng(0).bytes(48)]
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    sent = garbage_sent = garbage_refused = i = 0
    clock = follow_loop_clock(node)
    # the loop's readers matched (the flood reaches them) and, with AFTER_CLOCK_S, the loop that
    # far (it runs meanwhile, however fast the machine)
    after_ns = round(float(sys.argv[5]) * 1e9) if len(sys.argv) > 5 else 0
    readers = int(sys.argv[6]) if len(sys.argv) > 6 else 1
    deadline = time.monotonic() + 60
    while (time.monotonic() < deadline and not stop and (clock[0] < after_ns or not all(
            pub.get_subscription_count() >= readers
            for t, pub in pubs.items() if t not in UNREAD))):
        node.spin_once(0.001)
    print("ready", flush=True)
    t0 = time.monotonic()
    while not stop and time.monotonic() - t0 < seconds:
        ahead = i / rate - (time.monotonic() - t0)
        if ahead > 0:                   # a spin ends early on data (a flooded /clock): again
            node.spin_once(ahead)
            continue
        for t, pub in pubs.items():
            if i % 101 == 7:         # every topic in turn, every kind in turn
                kinds = [*garbage, whole[t][: len(whole[t]) // 2]]
                data = kinds[(i // 101) % len(kinds)]
                try:
                    pub.publish(data)
                    garbage_sent += 1
                except Exception:       # Cyclone's writer refuses bytes it cannot parse
                    garbage_refused += 1
            else:
                pub.publish(hostile(messages, t, i, clock[0]))
                sent += 1
            i += 1
    rate_out = i / (time.monotonic() - t0)
    print("sent", sent, garbage_sent, garbage_refused, f"{rate_out:.0f}", flush=True)


if __name__ == "__main__":
    main()
