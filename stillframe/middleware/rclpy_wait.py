"""The rclpy nodes' wait: one rcl wait set for a process's subscriptions, their samples taken and
handed to the callbacks directly, as the ``dds`` backend's ``spin_once`` does.

rclpy's ``SingleThreadedExecutor`` builds a new wait set in Python on every ``spin_once`` and runs
each message as a ``Task``, one message per call, several times the cost of this wait
(``stillframe bench hops`` times both; docs/realtime.md, "rclpy's executor"). Its C++
``EventsExecutor`` is not usable in Jazzy (rclpy 7.1.6): it fails with "SystemError: null argument
to internal routine" on every subscription whose callback takes a ``MessageInfo``, and it ignores
callback groups (ros2/rclpy#1478), so it would take the polled subscriptions' samples.

The subscriptions made through the node API are in :data:`SUBSCRIPTIONS_WAITED_HERE`, a callback
group rclpy's executor never runs. The wait set holds them and, so that a wait also ends for
them, the nodes' other subscriptions (rclpy's own, such as ``/clock`` with ``use_sim_time``),
timers, services and clients, which rclpy's executor then runs, one callback per call as
before. The executor also runs every :data:`EXECUTOR_POLL_NS` for what this wait set leaves
out: QoS events and guard conditions.
"""

from __future__ import annotations

import contextlib
import time
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

#: how often rclpy's executor runs when nothing in this wait set asked for it
EXECUTOR_POLL_NS = 1_000_000_000


class NeverExecuted(CallbackGroup):
    """A callback group rclpy's executor never runs: its subscriptions stay out of the
    executor's wait set (they are taken by :class:`SubscriptionWait`, or by polling)."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        """Nothing runs, so nothing ends."""


#: subscriptions taken by :class:`SubscriptionWait`
SUBSCRIPTIONS_WAITED_HERE = NeverExecuted()
#: subscriptions nobody waits for: taken when their owner polls
NEVER_EXECUTED = NeverExecuted()


class SubscriptionWait:
    """One process's wait over the entities of its nodes, beside rclpy's ``executor``."""

    def __init__(self, executor: SingleThreadedExecutor) -> None:
        self.executor = executor
        self._nodes: list[Any] = []
        self._wait_set: Any = None
        self._sizes: tuple[int, ...] = ()
        self._next_poll_ns = 0

    def add_node(self, node: Any) -> None:
        self.executor.add_node(node)
        self._nodes.append(node)

    def remove_node(self, node: Any) -> None:
        self.executor.remove_node(node)
        self._nodes.remove(node)

    def spin_once(self, timeout_ns: int) -> None:
        """Wait up to ``timeout_ns`` for a sample, a timer, a request or a response. Take every
        sample of each ready subscription of :data:`SUBSCRIPTIONS_WAITED_HERE` into its
        callback (subscriptions in creation order); let rclpy's executor run one callback if
        anything else is ready. ``timeout_ns`` 0 only takes what the subscriptions hold: rmw's
        wait costs a timed futex wait in Fast DDS even then, several times what empty takes cost."""
        own, executed = [], []
        for node in self._nodes:
            for sub in node._subscriptions:
                if sub.callback_group is SUBSCRIPTIONS_WAITED_HERE:
                    own.append(sub)
                elif sub.callback_group is not NEVER_EXECUTED:
                    executed.append(sub)
        if timeout_ns == 0 and time.monotonic_ns() < self._next_poll_ns:
            for sub in own:
                self._take_all(sub)
            return
        timers = [t for node in self._nodes for t in node._timers]
        services = [s for node in self._nodes for s in node._services]
        clients = [c for node in self._nodes for c in node._clients]
        wait_set = self._wait_set_for(len(own) + len(executed), len(timers), len(services),
                                      len(clients))
        wait_set.clear_entities()
        for sub in own:
            wait_set.add_subscription(sub.handle)
        for sub in executed:
            wait_set.add_subscription(sub.handle)
        for timer in timers:
            wait_set.add_timer(timer.handle)
        for service in services:
            wait_set.add_service(service.handle)
        for client in clients:
            wait_set.add_client(client.handle)
        wait_set.wait(timeout_ns)
        ready = wait_set.get_ready_entities("subscription")
        others_ready = any(sub.handle.pointer in ready for sub in executed)
        for sub in [sub for sub in own if ready and sub.handle.pointer in ready]:
            self._take_all(sub)
        now = time.monotonic_ns()
        if (now >= self._next_poll_ns or others_ready
                or wait_set.get_ready_entities("timer")
                or wait_set.get_ready_entities("service")
                or wait_set.get_ready_entities("client")):
            self._next_poll_ns = now + EXECUTOR_POLL_NS
            self.executor.spin_once(timeout_sec=0)

    def _wait_set_for(self, *sizes: int) -> Any:
        """The wait set, made again when the number of entities changed."""
        if sizes != self._sizes:
            subscriptions, timers, services, clients = sizes
            context = self.executor.context.handle
            self._wait_set = _rclpy.WaitSet(subscriptions, 0, timers, clients, services, 0,
                                            context)
            self._sizes = sizes
        return self._wait_set

    @staticmethod
    def _take_all(sub: Any) -> None:
        """Every sample ``sub`` holds, oldest first, into its callback (``(data, info)``); none
        if an earlier callback of this wait destroyed it (as rclpy's executor skips it)."""
        with contextlib.suppress(InvalidHandle), sub.handle:
            while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                sub.callback(*taken)
