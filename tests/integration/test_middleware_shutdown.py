"""SIGINT and SIGTERM stop a spinning node cleanly: exit code 0, no traceback, entities released
(the node's publisher disappears from the graph at once instead of at lease expiry)."""

from __future__ import annotations

import signal
import time

import pytest

from stillframe.middleware.api import create_node, spin_until
from tests.support.middleware import finish, start_python, wait_for_line

NODE = """
import sys
from stillframe.contract import messages
from stillframe.middleware.api import create_node, node_main, spin

def main():
    node = create_node("stopper", namespace="/frame")
    pub = node.create_publisher("sensor_msgs/msg/Imu", "floor1/imu", "sensor_data")
    node.create_subscription("sensor_msgs/msg/JointState", "cmd", lambda m: None, "default")
    node.create_timer(0.01, lambda: pub.publish(messages.new("sensor_msgs/msg/Imu")))
    print("ready", flush=True)
    spin(node)
    node.destroy_node()
    print("clean exit", flush=True)

sys.exit(node_main(main)())
"""


def publishers(node: object) -> int:
    return len(node.get_publishers_info_by_topic("/frame/floor1/imu"))


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_the_node_cleanly(ros_domain: int, signum: int) -> None:
    observer = create_node("observer", argv=["test"])
    proc = start_python(NODE)
    try:
        wait_for_line(proc, "ready")
        assert spin_until(observer, lambda: publishers(observer) == 1, 15)
        proc.send_signal(signum)
        out, err = finish(proc)
        assert proc.returncode == 0, err
        assert "Traceback" not in err
        assert "clean exit" in out
        # Deleted entities are announced: gone well before Cyclone's 10 s lease would expire.
        assert spin_until(observer, lambda: publishers(observer) == 0, 5)
    finally:
        observer.destroy_node()


def test_a_killed_node_lingers_until_its_lease_expires(ros_domain: int) -> None:
    """The control case of the test above: SIGKILL releases nothing, so the publisher stays
    visible for a while - the clean-exit check can tell the difference."""
    observer = create_node("observer", argv=["test"])
    proc = start_python(NODE)
    try:
        wait_for_line(proc, "ready")
        assert spin_until(observer, lambda: publishers(observer) == 1, 15)
        proc.send_signal(signal.SIGKILL)
        finish(proc)
        assert proc.returncode == -signal.SIGKILL
        start = time.monotonic()
        spin_until(observer, lambda: time.monotonic() - start > 2.0, 3)
        assert publishers(observer) == 1
    finally:
        observer.destroy_node()
