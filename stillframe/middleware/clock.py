"""Time and clocks: system time, ROS time following ``/clock`` (``use_sim_time``), and a
``/clock`` publisher helper for simulators.

As in rclcpp/rclpy, a node with ``use_sim_time`` reads the latest ``rosgraph_msgs/msg/Clock``
on ``/clock`` (QoS ``clock``); until the first one arrives its time is zero and its timers do
not fire.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from stillframe.contract import messages
from stillframe.contract.fixed_cdr import FixedWriter
from stillframe.middleware.taps import TappedPublisher


@dataclass(frozen=True, order=True)
class Time:
    """A point in time, integer nanoseconds (like ``rclpy.time.Time``)."""

    nanoseconds: int = 0

    def to_msg(self) -> Any:
        """``builtin_interfaces/msg/Time``."""
        return messages.time_msg(self.nanoseconds)

    @classmethod
    def from_msg(cls, msg: Any) -> Time:
        """The time a ``builtin_interfaces/msg/Time`` holds (its ``sec`` and ``nanosec``)."""
        return cls(messages.stamp_ns(msg))

    def seconds_nanoseconds(self) -> tuple[int, int]:
        """Whole seconds and the nanoseconds left over, as ``rclpy.time.Time.seconds_nanoseconds``
        returns them."""
        return divmod(self.nanoseconds, 1_000_000_000)

    @property
    def seconds(self) -> float:
        """The time in seconds, a float (:attr:`nanoseconds` holds it exactly)."""
        return self.nanoseconds * 1e-9


class Clock:
    """System time, or ROS time driven by ``/clock`` when ``sim`` is set."""

    def __init__(self, sim: bool = False) -> None:
        self.sim = sim
        self._sim_ns = 0

    def now(self) -> Time:
        """The current time: the latest ``/clock`` with ``sim`` (zero before the first), else the
        system time since the Unix epoch."""
        return Time(self.now_ns())

    def now_ns(self) -> int:
        """:meth:`now` in nanoseconds, without the :class:`Time` (once per received sample)."""
        return self._sim_ns if self.sim else time.time_ns()

    def set_sim_time(self, nanoseconds: int) -> None:
        """Advance sim time (called for each ``/clock`` message)."""
        self._sim_ns = nanoseconds

    @property
    def started(self) -> bool:
        """False while a sim clock has not received its first ``/clock``."""
        return not self.sim or self._sim_ns > 0


#: The wall clock, for timers that must run on real time even in a sim-time node.
SYSTEM_CLOCK = Clock(sim=False)


class ClockPublisher:
    """Publishes ``/clock`` (QoS ``clock``, with a monitor tap) for the nodes that use sim time."""

    TOPIC = "/clock"
    TYPE = "rosgraph_msgs/msg/Clock"

    def __init__(self, node: Any) -> None:
        self._pub = TappedPublisher(node, self.TYPE, self.TOPIC, "clock")
        self._cdr = FixedWriter(messages.new(self.TYPE), ("clock.sec", "clock.nanosec"))

    def publish(self, t: Time | int) -> None:
        """Publish sim time ``t`` (a Time or integer nanoseconds)."""
        ns = t.nanoseconds if isinstance(t, Time) else int(t)
        self._pub.publish(self._cdr.pack(*divmod(ns, 1_000_000_000)))
