"""Hostile inputs (issue 11, item 5) during a lock-step LQG run through the three nodes:

- a real rclpy node sends NaN, ±Inf, 1e308, stamps of zero, negative and far in the future, and a
  1 MB ``frame_id`` on the topics this loop does not use (``floor3/force_cmd``,
  ``floor3/load_cell``: LQG drives the pendulum torque): the sim refuses them by reason
  (``inactive_actuator``), the estimator ignores them;

and the run equals the undisturbed one-process loop to the last bit. Truncated and garbage CDR
are dropped and counted by the delivery path every subscription uses (``malformed_samples`` in
each node's ``/diagnostics``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stillframe.contract import messages, topics
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.middleware import api
from tests.support.nodes import SHORT_LQG, run_loop_beside
from tests.support.scenes import thesis_scene

RCLPY_WRITER = """
import math, signal
import rclpy
from geometry_msgs.msg import WrenchStamped
rclpy.init()
node = rclpy.create_node("hostile_writer", namespace="/frame")
pubs = [node.create_publisher(WrenchStamped, t, 10) for t in ("floor3/force_cmd",
                                                               "floor3/load_cell")]
stop = []
signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
values = [math.nan, math.inf, -math.inf, 1e308, 0.5]
stamps = [(0, 0), (-5, 0), (2_000_000_000, 0), (1, 0)]
big = "x" * 1_000_000
sent = 0
print("ready", flush=True)
while not stop:
    for value in values:
        for sec, nsec in stamps:
            msg = WrenchStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
            msg.header.frame_id = big if sent % 4000 == 0 else ""
            msg.wrench.force.x = value
            for pub in pubs:
                pub.publish(msg)
                sent += 1
    rclpy.spin_once(node, timeout_sec=0.02)
print("sent", sent, flush=True)
"""


@pytest.mark.slow
def test_garbage_and_hostile_values_change_nothing(ros_domain: int, tmp_path: Path) -> None:
    result, hist, sent = run_loop_beside(tmp_path, RCLPY_WRITER, "thesis_lqg", SHORT_LQG,
                                         command_writer="controller_node",
                                         diagnostics_period_s=0.2)
    assert sent > 0
    reference = run_closed_loop(thesis_scene("thesis_lqg", SHORT_LQG))
    np.testing.assert_array_equal(hist["truth"], reference.truth)
    np.testing.assert_array_equal(hist["command"], reference.command)
    assert result["reduction_pct"] == reference.evaluation["reduction_pct"]
    force_gate = result["command_gates"]["floor3/force_cmd"]
    assert force_gate["rejected_inactive_actuator"] > 0
    torque_gate = result["command_gates"]["pendulum/torque_cmd"]
    assert torque_gate["writer"] == "/frame/controller_node"


@pytest.mark.parametrize("kind", [s.type_name for s in (
    topics.FLOOR_IMU[0], topics.PENDULUM_JOINT_STATES, topics.EXCITATION_WRENCH,
    topics.TORQUE_CMD, topics.STATE_ESTIMATE)])
def test_truncated_and_garbage_cdr_is_dropped_and_counted(kind: str) -> None:
    """What every subscription of both backends does with bytes that do not decode (Cyclone's
    own writer refuses to send such bytes, so they are fed to the delivery path directly)."""
    whole = messages.serialize(messages.new(kind))
    rng = np.random.default_rng(0)
    bad = [whole[: len(whole) // 2], b"", b"\x00\x01\x00\x00",
           b"\x00\x01\x00\x00" + rng.integers(0, 256, 48, dtype=np.uint8).tobytes()]
    got: list = []
    before = api.MALFORMED["/hostile"]
    for data in [*bad, whole]:
        api.deliver(got.append, data, kind, "/hostile")
    assert len(got) == 1 and api.MALFORMED["/hostile"] - before == len(bad)
