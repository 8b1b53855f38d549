"""A plain rclpy client in the test process (its own rclpy context), reading the loop's torque
commands: the independent peer of the tests that drive rclpy-backend nodes through their
standard services."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any


@dataclass
class RclpyClient:
    """rclpy's node and executor of the test, and the torques it has received so far."""

    node: Any
    executor: Any
    torques: list[float] = field(default_factory=list)

    def next_torques(self, count: int, timeout_s: float = 60) -> list[float]:
        """The next ``count`` torque commands (spinning until they are in)."""
        start = len(self.torques)
        deadline = time.monotonic() + timeout_s
        while len(self.torques) < start + count and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        assert len(self.torques) >= start + count, f"only {len(self.torques) - start} commands"
        return self.torques[start:start + count]

    def done(self, future: Any) -> Any:
        """The result of ``future``, spun until it is done (30 s at most)."""
        self.executor.spin_until_future_complete(future, timeout_sec=30)
        assert future.done()
        return future.result()


@contextmanager
def rclpy_client(name: str, depth: int = 10) -> Iterator[RclpyClient]:
    """A client node subscribed to ``/frame/pendulum/torque_cmd`` (keep last ``depth``)."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node(name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    client = RclpyClient(node, executor)
    node.create_subscription(WrenchStamped, "/frame/pendulum/torque_cmd",
                             lambda m: client.torques.append(m.wrench.torque.z), depth)
    try:
        yield client
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
