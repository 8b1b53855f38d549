"""A foreign writer on the loop's command and controller-input topics (issue 39, item 3), run as
``python tests/support/foreign_writer.py BACKEND NAME NAMESPACE RATE [FROM_CLOCK_S]``.

A plain node ``NAMESPACE/NAME`` (``/rogue_tuner``, or ``/controller_node``: the controller's name
in the root namespace) on BACKEND (``rclpy``: real rclpy on Fast DDS; ``dds``: a Cyclone writer
of ours) writing plausible samples at RATE per second on each of ``/frame/pendulum/torque_cmd``
(2 sin 7t N m), ``/frame/state_estimate`` and ``/frame/excitation/wrench``, every one stamped
with the loop's newest ``/clock`` (a stamp the loop would take), ``frame_id`` as a tool leaves
it (``pendulum``, ``""``, ``floor1``). It writes from its start (the loop not there yet: the first
writer on every topic), or, with FROM_CLOCK_S, once the loop's ``/clock`` has passed that time.
Prints ``ready`` once it has written 50 samples on each topic (or, with FROM_CLOCK_S, at
once), writes until SIGTERM, then prints ``sent N`` (every topic's samples together).
"""

from __future__ import annotations

import math
import os
import signal
import sys
import time

TOPICS = {"/frame/pendulum/torque_cmd": ("geometry_msgs/msg/WrenchStamped", "pendulum"),
          "/frame/state_estimate": ("sensor_msgs/msg/JointState", ""),
          "/frame/excitation/wrench": ("geometry_msgs/msg/WrenchStamped", "floor1")}
READY_AFTER = 50


def main() -> None:
    backend, name, namespace, rate = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
    from_ns = round(float(sys.argv[5]) * 1e9) if len(sys.argv) > 5 else None
    os.environ["STILLFRAME_RMW"] = backend
    import numpy as np

    from stillframe.contract import messages
    from stillframe.middleware import api
    from stillframe.middleware.qos import Durability, QoSProfile, Reliability

    # reliable and transient-local: it matches every reader of the loop, each mode's
    qos = QoSProfile(depth=10, reliability=Reliability.RELIABLE,
                     durability=Durability.TRANSIENT_LOCAL)
    node = api.create_node(name, namespace=namespace, argv=["foreign"])
    pubs = {topic: node.create_publisher(kind, topic, qos) for topic, (kind, _) in TOPICS.items()}
    clock = [0]

    def on_clock(msg: object) -> None:
        clock[0] = messages.stamp_ns(msg.clock)

    node.create_subscription("rosgraph_msgs/msg/Clock", "/clock", on_clock, "clock")
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    if from_ns is not None:
        print("ready", flush=True)
    sent, t0 = 0, time.monotonic()
    while not stop:
        if from_ns is not None and clock[0] < from_ns:     # the loop not that far yet
            node.spin_once(0.01)
            t0 = time.monotonic()
            continue
        node.spin_once(max(0.0, t0 + sent / rate - time.monotonic()))
        t = time.monotonic() - t0
        if t < sent / rate:
            continue
        for topic, (kind, frame) in TOPICS.items():
            msg = messages.new(kind)
            msg.header.stamp = messages.time_msg(clock[0])
            msg.header.frame_id = frame
            if topic.endswith("torque_cmd"):
                msg.wrench.torque.z = 2.0 * math.sin(7.0 * t)
            elif topic.endswith("wrench"):
                msg.wrench.force.x = 5.0 * math.sin(11.0 * t)
            else:
                msg.name = ["x1", "x2", "x3", "phi"]
                msg.position, msg.velocity = np.full(4, 0.01), np.full(4, -0.02)
            pubs[topic].publish(msg)
        sent += 1
        if sent == READY_AFTER and from_ns is None:
            print("ready", flush=True)
    print("sent", sent * len(TOPICS), flush=True)
    node.destroy_node()


if __name__ == "__main__":
    main()
