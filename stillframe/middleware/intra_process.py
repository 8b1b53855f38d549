"""Intra-process delivery between the nodes of one process, as rclcpp's intra-process comms.

When a process composes several nodes (``container_node``, ``stillframe launch --compose``), a raw
subscription of a topic gets the CDR bytes that a publisher of the same process writes handed to
its callback as they are written, in the writer's thread: no DDS take, no wake-up, no second
decoding path (the subscription's own reader reads the same bytes). The DDS reader of such a
subscription ignores the process's own writers (Cyclone's IgnoreLocal), so nothing comes twice;
samples of other processes' writers still come through DDS, and the writes still go out to
every other reader (recorder, monitor). Each publisher and subscription counts its in-process
peers with its DDS matches, so the lock-step start-up checks see them as matched.

Off unless :func:`enable` is called before the nodes are made.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable

#: ``deliver(cdr, source_timestamp_ns, publisher_gid)`` of an in-process raw subscription
Delivery = Callable[[bytes, int, bytes], None]

_enabled = False
_subscriptions: defaultdict[str, list[Delivery]] = defaultdict(list)
_publishers: defaultdict[str, int] = defaultdict(int)


def enable() -> None:
    """Hand samples over in-process from now on (for nodes made after this call)."""
    global _enabled
    _enabled = True


def enabled() -> bool:
    """Whether :func:`enable` was called in this process (nodes then hand samples over
    in-process)."""
    return _enabled


def subscribe(topic: str, deliver: Delivery) -> None:
    """Add ``deliver`` to the in-process subscriptions of ``topic``: every later write of a
    publisher of this process on ``topic`` calls it."""
    _subscriptions[topic].append(deliver)


def unsubscribe(topic: str, deliver: Delivery) -> None:
    """Remove ``deliver`` from the in-process subscriptions of ``topic`` (``ValueError`` if it was
    not there)."""
    _subscriptions[topic].remove(deliver)


def add_publisher(topic: str) -> None:
    """Count one more publisher of ``topic`` in this process (what :func:`publisher_count`
    returns)."""
    _publishers[topic] += 1


def remove_publisher(topic: str) -> None:
    """Count one publisher of ``topic`` fewer, as a destroyed publisher does."""
    _publishers[topic] -= 1


def subscriptions(topic: str) -> list[Delivery]:
    """The in-process subscriptions of ``topic``: the list itself, which later subscriptions
    join (a publisher keeps it; empty for most topics)."""
    return _subscriptions[topic]


def subscription_count(topic: str) -> int:
    """How many in-process subscriptions ``topic`` has, added to a publisher's DDS matches."""
    return len(_subscriptions.get(topic, ()))


def publisher_count(topic: str) -> int:
    """How many publishers of this process write ``topic``, added to a subscription's DDS
    matches."""
    return _publishers.get(topic, 0)
