"""Sim time: a node with ``use_sim_time`` follows ``/clock`` (timers and stamps), here with a
clock running 10x faster than real time."""

from __future__ import annotations

from stillframe.contract import messages
from stillframe.middleware.api import create_node, spin_until
from stillframe.middleware.clock import SYSTEM_CLOCK, ClockPublisher
from tests.support.waits import HANG_S

SIM_START_NS = 1000 * 10**9   # sim time starts at 1000 s, far from the wall clock's epoch time
CLOCK_STEP_NS = 100 * 10**6   # every 10 ms of wall time, sim time advances 100 ms: 10x
TIMER_PERIOD_S = 0.2          # on sim time
SIM_SPAN_NS = 10 * 10**9


def test_timers_and_stamps_follow_a_10x_clock(ros_domain: int) -> None:
    simulator = create_node("simulator", argv=["test"])
    follower = create_node("follower", argv=["test", "--ros-args", "-p", "use_sim_time:=true"])
    try:
        clock_pub = ClockPublisher(simulator)
        sim_ns = [SIM_START_NS]
        stamps: list[int] = []
        out = follower.create_publisher("std_msgs/msg/Header", "ticks", "default")

        def tick() -> None:  # stamps the way every node does: from its own clock
            now = follower.get_clock().now()
            stamps.append(now.nanoseconds)
            out.publish(messages.new("std_msgs/msg/Header", stamp=now.to_msg()))

        follower.create_timer(TIMER_PERIOD_S, tick)

        def advance() -> None:
            sim_ns[0] += CLOCK_STEP_NS
            clock_pub.publish(sim_ns[0])

        received: list[int] = []
        simulator.create_subscription("std_msgs/msg/Header", "ticks",
                                      lambda h: received.append(messages.stamp_ns(h.stamp)), 100)
        spin_until(follower, lambda: False, 0.3)
        # No /clock yet: sim time is 0 and the sim-time timer has not fired.
        assert follower.get_clock().now().nanoseconds == 0 and stamps == []
        clock_pub.publish(SIM_START_NS)
        assert spin_until(follower, lambda: follower.get_clock().now().nanoseconds > 0, HANG_S)
        simulator.create_timer(CLOCK_STEP_NS / 10 * 1e-9, advance, clock=SYSTEM_CLOCK)
        end = SIM_START_NS + SIM_SPAN_NS

        def step_both() -> bool:
            simulator.spin_once(0.002)
            follower.spin_once(0.002)
            return follower.get_clock().now().nanoseconds >= end

        assert spin_until(follower, step_both, HANG_S)
        period_ns = round(TIMER_PERIOD_S * 1e9)
        # Every call at an exact multiple of the period after the first /clock: the timer runs
        # on sim time (on wall time, 10 s of sim would be ~1 s of wall: ~5 calls, not 50).
        assert stamps == [SIM_START_NS + k * period_ns for k in range(1, 51)][: len(stamps)]
        assert len(stamps) >= 49
        spin_until(simulator, lambda: len(received) == len(stamps), 5)
        assert received == stamps  # the published header stamps are sim time too
    finally:
        follower.destroy_node()
        simulator.destroy_node()
