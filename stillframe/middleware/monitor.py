"""Watching topics from a tool: discovering a topic's type and QoS, printing messages as YAML,
receive-rate statistics (what ``stillframe topic`` shows, shaped like ``ros2 topic``'s)."""

from __future__ import annotations

import statistics
import sys
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import yaml

from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.middleware import api, names
from stillframe.middleware.graph import ANNOUNCE_S
from stillframe.middleware.qos import DEFAULT, Durability, QoSProfile, Reliability


def wait_for_publisher(
    node: api.Node, topic: str, timeout: float | None,
    on_missing: Callable[[str], bool | None] | None = None,
) -> tuple[str, QoSProfile]:
    """The type of ``topic`` and a QoS compatible with all its publishers (like ``ros2 topic``:
    reliable/transient-local only if every publisher offers it). ``on_missing(full_name)`` is
    called once if this node found no publisher in the first half second (it may raise): whether
    a settled graph (the daemon's) shows one, or None when it cannot say, and this node's own
    discovery is then given one announcement period (:data:`.graph.ANNOUNCE_S`). ros2's ``does
    not appear to be published yet`` is printed only when neither shows a publisher: a fresh
    node finds a running topic's publishers only after a second or more."""
    full = names.resolve_topic(topic)
    found: list[api.TopicEndpointInfo] = []
    deadline = time.monotonic() + (1e9 if timeout is None else timeout)

    def discovered() -> bool:
        found[:] = node.get_publishers_info_by_topic(full)
        return bool(found)

    def left(at_most: float = 1e9) -> float:
        return max(min(deadline - time.monotonic(), at_most), 0.0)

    if not api.spin_until(node, discovered, left(0.5)):
        published = on_missing(full) if on_missing is not None else None
        if published is None:
            published = api.spin_until(node, discovered, left(ANNOUNCE_S))
        if not published:
            print(f"WARNING: topic [{full}] does not appear to be published yet",
                  file=sys.stderr)
        if not api.spin_until(node, discovered, left()):
            if api.ok():
                raise InputError(f"no publisher of topic {full} appeared within {timeout:g} s")
            return "", DEFAULT
    types = sorted({ep.topic_type for ep in found})
    if len(types) > 1:
        raise InputError(f"topic {full} is published with several types: {', '.join(types)}")
    reliable = all(ep.qos_profile.reliability == Reliability.RELIABLE for ep in found)
    latched = all(ep.qos_profile.durability == Durability.TRANSIENT_LOCAL for ep in found)
    qos = QoSProfile(
        depth=10,
        reliability=Reliability.RELIABLE if reliable else Reliability.BEST_EFFORT,
        durability=Durability.TRANSIENT_LOCAL if latched else Durability.VOLATILE,
    )
    return types[0], qos


def select_field(msg: Any, path: str | None) -> Any:
    """The nested field ``a.b`` of a message (InputError naming the missing part)."""
    value = msg
    for part in path.split(".") if path else ():
        kind = getattr(value, "__msgtype__", None)
        if kind is None or part not in dict(messages.fielddefs(kind)):
            kind = kind or type(value).__name__
            raise InputError(f"--field {path}: {kind} has no field {part!r}")
        value = getattr(value, part)
    return value


def to_yaml(value: Any) -> str:
    """The YAML ``ros2 topic echo`` prints for a message or field."""
    return yaml.safe_dump(messages.to_plain(value), sort_keys=False, default_flow_style=False,
                          allow_unicode=True, explicit_end=False).removesuffix("...\n")


def rate_report(stamps_ns: deque[int]) -> str | None:
    """``ros2 topic hz``'s two lines for receive times in ns (None with fewer than 2)."""
    if len(stamps_ns) < 2:
        return None
    gaps = [(b - a) * 1e-9 for a, b in zip(stamps_ns, list(stamps_ns)[1:], strict=False)]
    mean = statistics.fmean(gaps)
    return (f"average rate: {1.0 / mean:.3f}\n"
            f"\tmin: {min(gaps):.3f}s max: {max(gaps):.3f}s "
            f"std dev: {statistics.pstdev(gaps):.5f}s window: {len(gaps) + 1}")
