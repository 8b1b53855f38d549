"""SIGINT and SIGTERM stop a spinning node cleanly: exit code 0, no traceback, entities released
(the node's publisher disappears from the graph at once instead of at lease expiry).

The node's participant announces a lease of twice :data:`HANG_S`, so a publisher that goes from
the graph within the wait went because the node said so, never because its lease ran out,
however long a loaded machine takes to show it."""

from __future__ import annotations

import signal
import time

import pytest

from stillframe.middleware.api import create_node, spin_until
from tests.support.middleware import finish, start_python, wait_for_line
from tests.support.waits import HANG_S

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


#: Cyclone's participant lease for the node, in place of its default
LONG_LEASE = {"CYCLONEDDS_URI": f"<CycloneDDS><Domain><Discovery><LeaseDuration>{2 * HANG_S:g} s"
                                "</LeaseDuration></Discovery></Domain></CycloneDDS>"}
#: Cyclone's default participant lease [s]
DEFAULT_LEASE_S = 10.0


def publishers(node: object) -> int:
    return len(node.get_publishers_info_by_topic("/frame/floor1/imu"))


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_the_node_cleanly(ros_domain: int, signum: int) -> None:
    observer = create_node("observer", argv=["test"])
    proc = start_python(NODE, env=LONG_LEASE)
    try:
        wait_for_line(proc, "ready")
        assert spin_until(observer, lambda: publishers(observer) == 1, HANG_S)
        proc.send_signal(signum)
        out, err = finish(proc)
        assert proc.returncode == 0, err
        assert "Traceback" not in err
        assert "clean exit" in out
        # deleted entities are announced: gone long before the lease could expire
        assert spin_until(observer, lambda: publishers(observer) == 0, HANG_S)
    finally:
        observer.destroy_node()


def test_a_killed_node_lingers_until_its_lease_expires(ros_domain: int) -> None:
    """The control case of the test above: SIGKILL releases nothing, so the publisher stays
    visible, here for longer than Cyclone's default lease: the node took the long one, and the
    clean-exit check can tell an announcement from a lease that ran out."""
    observer = create_node("observer", argv=["test"])
    proc = start_python(NODE, env=LONG_LEASE)
    try:
        wait_for_line(proc, "ready")
        assert spin_until(observer, lambda: publishers(observer) == 1, HANG_S)
        proc.send_signal(signal.SIGKILL)
        finish(proc)
        assert proc.returncode == -signal.SIGKILL
        start = time.monotonic()
        spin_until(observer, lambda: time.monotonic() - start > 1.5 * DEFAULT_LEASE_S, HANG_S)
        assert publishers(observer) == 1
    finally:
        observer.destroy_node()
