"""The rclpy backend (real rclpy on Fast DDS, from PyPI): the same round trip as the dds
backend, and its wait (:mod:`stillframe.middleware.rclpy_wait`) beside rclpy's executor."""

from __future__ import annotations

import time

import pytest

rclpy = pytest.importorskip(
    "rclpy", reason="rclpy is not importable (not on PyPI/Debian): the rclpy backend is untested"
)

from stillframe.contract import messages  # noqa: E402
from stillframe.middleware import rclpy_wait  # noqa: E402
from stillframe.middleware.api import create_node, spin_until  # noqa: E402
from stillframe.middleware.clock import SYSTEM_CLOCK, ClockPublisher  # noqa: E402
from stillframe.middleware.qos import SENSOR_DATA, Durability, Reliability  # noqa: E402
from tests.support.waits import HANG_S  # noqa: E402


def test_round_trip_over_rclpy(ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    node = create_node("rclpy_check", namespace="/frame",
                       argv=["test", "--ros-args", "-p", "gain:=2.5"])
    try:
        assert node.backend == "rclpy"
        assert node.declare_parameter("gain", 1.0).value == 2.5
        got: list = []
        raw: list = []
        pub = node.create_publisher("sensor_msgs/msg/JointState", "js", "default")
        node.create_subscription("sensor_msgs/msg/JointState", "js", got.append, "default")
        node.create_subscription("sensor_msgs/msg/JointState", "js",
                                 lambda data, info: raw.append((data, info)), SENSOR_DATA,
                                 raw=True)
        assert spin_until(node, lambda: pub.get_subscription_count() == 2, HANG_S)
        msg = messages.new("sensor_msgs/msg/JointState", name=["phi"], position=[0.5])
        before = time.time_ns()
        pub.publish(msg)
        after = time.time_ns()
        assert spin_until(node, lambda: got and raw, HANG_S)
        assert got[0].name == ["phi"] and got[0].position.tolist() == [0.5]
        data, info = raw[0]
        assert messages.deserialize(data, "sensor_msgs/msg/JointState").position[0] == 0.5
        # the writer's source timestamp (inside the publish call), not the receive time
        assert before <= info.source_timestamp <= after <= info.received_timestamp
        topics = dict(node.get_topic_names_and_types())
        assert topics["/frame/js"] == ["sensor_msgs/msg/JointState"]
        info = node.get_publishers_info_by_topic("/frame/js")[0]
        assert info.node_name == "rclpy_check"
        # DDS discovery does not carry history or depth: rmw reports them UNKNOWN / 0
        assert info.qos_profile.reliability == Reliability.RELIABLE
        assert info.qos_profile.durability == Durability.VOLATILE
    finally:
        node.destroy_node()


@pytest.mark.parametrize("timeout_sec", [1.0, 0.0])
def test_one_spin_takes_every_waiting_sample_in_order(
        ros_domain: int, monkeypatch: pytest.MonkeyPatch, timeout_sec: float) -> None:
    """rclpy's executor runs one callback per ``spin_once``; the backend's wait takes every
    sample that has arrived, each topic's in the order written, the topics in the order their
    subscriptions were made (as the dds backend); with no timeout, without rmw's wait."""
    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    monkeypatch.setattr(rclpy_wait, "EXECUTOR_POLL_NS", 3600 * 10**9)
    node = create_node("rclpy_wait_check", argv=["test"])
    try:
        got: list[tuple[str, str]] = []
        pubs = {name: node.create_publisher("std_msgs/msg/String", name, 10)
                for name in ("a", "b")}
        for name in ("b", "a"):
            node.create_subscription(
                "std_msgs/msg/String", name,
                lambda msg, name=name: got.append((name, msg.data)), 10)
        assert spin_until(node, lambda: all(p.get_subscription_count() for p in pubs.values()),
                          HANG_S)
        written = [("a", "1"), ("b", "1"), ("a", "2"), ("b", "2"), ("a", "3")]
        for name, data in written:
            pubs[name].publish(messages.new("std_msgs/msg/String", data=data))
        # acknowledged: every sample is in the subscriptions' histories before the one spin
        assert all(p.wait_for_all_acked(10.0) for p in pubs.values())
        node.spin_once(timeout_sec)
        assert got == [("b", "1"), ("b", "2"), ("a", "1"), ("a", "2"), ("a", "3")]
    finally:
        node.destroy_node()


def test_rclpy_s_own_clock_subscription_and_timers_still_run(
        ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """What the wait does not take itself, rclpy's executor runs when the wait ends for it:
    rclpy's ``/clock`` subscription of a node with ``use_sim_time``, and a timer. The
    executor's own polling is put off for an hour, so only the wait can make them run."""
    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    monkeypatch.setattr(rclpy_wait, "EXECUTOR_POLL_NS", 3600 * 10**9)
    follower = create_node("rclpy_sim_time", argv=["test", "--ros-args", "-p",
                                                   "use_sim_time:=true"])
    try:
        clock = ClockPublisher(follower)
        ticks: list[int] = []
        follower.create_timer(0.01, lambda: ticks.append(1), clock=SYSTEM_CLOCK)
        assert spin_until(follower, lambda: len(ticks) >= 3, HANG_S)
        sim_ns = 123_456_789_000
        # rclpy's time source keeps the latest /clock sample; published until it is read back
        assert spin_until(follower, lambda: clock.publish(sim_ns)
                          or follower.get_clock().now().nanoseconds == sim_ns, HANG_S)
    finally:
        follower.destroy_node()


def test_a_subscription_destroyed_by_an_earlier_callback_of_the_same_wait_is_skipped(
        ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    node = create_node("rclpy_wait_destroy", argv=["test"])
    try:
        got: list[str] = []
        pubs = [node.create_publisher("std_msgs/msg/String", name, 10) for name in ("a", "b")]
        subs: list = []
        subs.append(node.create_subscription(
            "std_msgs/msg/String", "a",
            lambda msg: (got.append(f"a{msg.data}"), node.destroy_subscription(subs[1])), 10))
        subs.append(node.create_subscription(
            "std_msgs/msg/String", "b", lambda msg: got.append(f"b{msg.data}"), 10))
        assert spin_until(node, lambda: all(p.get_subscription_count() for p in pubs), HANG_S)
        for pub in pubs:
            pub.publish(messages.new("std_msgs/msg/String", data="1"))
        assert all(p.wait_for_all_acked(10.0) for p in pubs)
        node.spin_once(1.0)
        node.spin_once(0.1)
        assert got == ["a1"]
    finally:
        node.destroy_node()
