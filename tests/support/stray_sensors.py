"""A stray simulator (issue 11): plausible sensor samples at the loop's own stamps, run as
``python tests/support/stray_sensors.py BACKEND FROM_S``. On every new ``/clock`` from FROM_S of
sim time on, it writes one sample on each sensor topic of the loop (``floor1..3/imu``,
``pendulum/joint_states``, ``excitation/wrench``) stamped with that ``/clock``: accelerations of
1 m/s², φ = 0.2 rad, 0.5 N m applied, 3 N on floor 1. It writes only while every topic's writer
is matched by the loop's readers (RELIABLE and TRANSIENT_LOCAL, a whole run deep, so each sample
written reaches them), and counts those stamps. ``BACKEND``: ``rclpy`` (a real rclpy peer on
Fast DDS) or ``dds`` (a Cyclone DDS writer of ours); the node is ``/frame/stray_sensors_BACKEND``.
Prints ``ready``, writes until SIGTERM, then prints ``sent STAMPS``.
"""

from __future__ import annotations

import os
import signal
import sys

import numpy as np

#: topic -> (type, readers of it in the LQG loop: the estimator; the controller too)
TOPICS = {**{f"floor{n}/imu": ("sensor_msgs/msg/Imu", 1) for n in (1, 2, 3)},
          "pendulum/joint_states": ("sensor_msgs/msg/JointState", 1),
          "excitation/wrench": ("geometry_msgs/msg/WrenchStamped", 2)}


def main() -> None:
    os.environ["STILLFRAME_RMW"] = sys.argv[1]
    from_ns = round(float(sys.argv[2]) * 1e9)
    from stillframe.contract import messages
    from stillframe.middleware import api
    from stillframe.middleware.qos import Durability, QoSProfile, Reliability
    from stillframe.node_runtime.support import FLOOD_DEPTH

    # what the loop's lock-step readers ask for, kept deep enough for a whole run: a writer
    # sees its reader matched before that reader has matched it (discovery is not symmetric),
    # and under load the gap spans many samples; a transient-local writer hands the reader every
    # sample it still keeps once the reader matches, so each sample written arrives (with depth
    # 5, 28 of a Fast DDS stray's 130 samples never reached a Cyclone estimator under two busy
    # loops)
    qos = QoSProfile(depth=FLOOD_DEPTH, reliability=Reliability.RELIABLE,
                     durability=Durability.TRANSIENT_LOCAL)
    node = api.create_node(f"stray_sensors_{sys.argv[1]}", namespace="/frame", argv=["w"])
    pubs = {t: node.create_publisher(kind, t, qos) for t, (kind, _) in TOPICS.items()}
    samples = {t: messages.new(kind) for t, (kind, _) in TOPICS.items()}
    for n in (1, 2, 3):
        samples[f"floor{n}/imu"].linear_acceleration.x = 1.0
    joints = samples["pendulum/joint_states"]
    joints.name, joints.position, joints.effort = ["pendulum"], np.array([0.2]), np.array([0.5])
    samples["excitation/wrench"].wrench.force.x = 3.0
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    sent, last = 0, -1

    def on_clock(msg: object) -> None:
        nonlocal sent, last
        ns = messages.stamp_ns(msg.clock)
        if ns < from_ns or ns == last or not all(
                pubs[t].get_subscription_count() >= readers for t, (_, readers) in TOPICS.items()):
            return
        for t, msg_out in samples.items():
            msg_out.header.stamp = messages.time_msg(ns)
            pubs[t].publish(msg_out)
        sent, last = sent + 1, ns

    node.create_subscription("rosgraph_msgs/msg/Clock", "/clock", on_clock, "clock")
    print("ready", flush=True)
    while not stop:
        node.spin_once(0.05)
    for pub in pubs.values():   # what it counted has reached the loop before it exits
        pub.wait_for_all_acked(30.0)
    print("sent", sent, flush=True)


if __name__ == "__main__":
    main()
