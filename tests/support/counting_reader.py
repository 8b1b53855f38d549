"""A reader that counts, run as ``python tests/support/counting_reader.py BACKEND``: it reads
``/frame/floor1/imu``, ``/frame/pendulum/joint_states`` and ``/frame/excitation/wrench``
(reliable, transient local) on ``BACKEND`` until SIGTERM and prints ``read GOOD MALFORMED``
(samples decoded, and samples dropped as malformed: by the delivery path every subscription
uses, and on the ``dds`` backend by Cyclone before it, counted from its log)."""

from __future__ import annotations

import os
import signal
import sys


def main() -> None:
    os.environ["STILLFRAME_RMW"] = sys.argv[1]
    from stillframe.middleware import api
    from stillframe.middleware.cyclone_log import count_deserialization_failures

    if sys.argv[1] == "dds":     # as a node executable does (api.node_main)
        count_deserialization_failures()
    from stillframe.middleware.qos import Durability, QoSProfile, Reliability

    qos = QoSProfile(depth=5, reliability=Reliability.RELIABLE,
                     durability=Durability.TRANSIENT_LOCAL)
    node = api.create_node(f"reader_{sys.argv[1]}", namespace="/frame", argv=["r"])
    got: list = []
    node.create_subscription("sensor_msgs/msg/Imu", "floor1/imu", got.append, qos)
    node.create_subscription("sensor_msgs/msg/JointState", "pendulum/joint_states", got.append,
                             qos)
    node.create_subscription("geometry_msgs/msg/WrenchStamped", "excitation/wrench", got.append,
                             qos)
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    print("ready", flush=True)
    while not stop:
        node.spin_once(0.05)
    print("read", len(got), sum(node.malformed.values()) + sum(api.CYCLONE_DROPPED.values()),
          flush=True)


if __name__ == "__main__":
    main()
