"""``stillframe topic list|echo|hz``: watch ROS 2 topics without ROS (like ``ros2 topic``)."""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections import deque
from typing import Any

import yaml

from stillframe import messages
from stillframe.errors import InputError
from stillframe.middleware import api, names
from stillframe.middleware.qos import DEFAULT, Durability, QoSProfile, Reliability


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("topic", help="list, echo and measure ROS 2 topics (like ros2 topic)")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True

    listing = verbs.add_parser("list", help="topics seen on the network")
    listing.add_argument("-t", "--show-types", action="store_true", help="also print types")
    listing.add_argument("--spin-time", type=float, default=1.0, metavar="S",
                         help="how long to wait for discovery (default 1 s)")
    listing.set_defaults(func=run_list)

    echo = verbs.add_parser("echo", help="print the messages of a topic as YAML")
    echo.add_argument("topic", metavar="TOPIC")
    echo.add_argument("--once", action="store_true", help="print one message and exit")
    echo.add_argument("--field", metavar="A.B", help="print only this (nested) field")
    add_wait_argument(echo)
    echo.set_defaults(func=run_echo)

    hz = verbs.add_parser("hz", help="print the receive rate of a topic")
    hz.add_argument("topic", metavar="TOPIC")
    hz.add_argument("--window", "-w", type=int, default=10000, metavar="N",
                    help="number of intervals in the statistics (default 10000)")
    hz.add_argument("--duration", type=float, metavar="S",
                    help="stop after S seconds (default: until Ctrl-C)")
    add_wait_argument(hz)
    hz.set_defaults(func=run_hz)


def add_wait_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--timeout", type=float, metavar="S",
                        help="give up if no publisher appears within S seconds (default: wait)")


def cli_node() -> api.Node:
    """A hidden node (name starting with '_') for a command-line tool."""
    return api.create_node(f"_stillframe_topic_{os.getpid()}", argv=["stillframe"])


def run_list(args: argparse.Namespace) -> int:
    node = cli_node()
    try:
        deadline = time.monotonic() + args.spin_time
        while api.ok() and time.monotonic() < deadline:
            node.spin_once(0.05)
        for topic, types in node.get_topic_names_and_types():
            print(f"{topic} [{', '.join(types)}]" if args.show_types else topic)
    finally:
        node.destroy_node()
    return 0


def wait_for_publisher(
    node: api.Node, topic: str, timeout: float | None
) -> tuple[str, QoSProfile]:
    """The type of ``topic`` and a QoS compatible with all its publishers (like ``ros2 topic``:
    reliable/transient-local only if every publisher offers it)."""
    full = names.resolve_topic(topic)
    found: list[api.TopicEndpointInfo] = []

    def discovered() -> bool:
        found[:] = node.get_publishers_info_by_topic(full)
        return bool(found)

    if not api.spin_until(node, discovered, 0.5 if timeout is None else min(timeout, 0.5)):
        print(f"WARNING: topic [{full}] does not appear to be published yet", file=sys.stderr)
        remaining = 1e9 if timeout is None else max(timeout - 0.5, 0.0)
        if not api.spin_until(node, discovered, remaining):
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


def run_echo(args: argparse.Namespace) -> int:
    node = cli_node()
    try:
        type_name, qos = wait_for_publisher(node, args.topic, args.timeout)
        if not type_name:
            return 0
        done: list[bool] = []

        def show(msg: Any) -> None:
            if done and args.once:
                return
            print(to_yaml(select_field(msg, args.field)) + "---", flush=True)
            done.append(True)

        node.create_subscription(type_name, names.resolve_topic(args.topic), show, qos)
        while api.ok() and not (args.once and done):
            node.spin_once(None)
    finally:
        node.destroy_node()
    return 0


def rate_report(stamps_ns: deque[int]) -> str | None:
    """``ros2 topic hz``'s two lines for receive times in ns (None with fewer than 2)."""
    if len(stamps_ns) < 2:
        return None
    gaps = [(b - a) * 1e-9 for a, b in zip(stamps_ns, list(stamps_ns)[1:], strict=False)]
    mean = statistics.fmean(gaps)
    return (f"average rate: {1.0 / mean:.3f}\n"
            f"\tmin: {min(gaps):.3f}s max: {max(gaps):.3f}s "
            f"std dev: {statistics.pstdev(gaps):.5f}s window: {len(gaps) + 1}")


def run_hz(args: argparse.Namespace) -> int:
    if args.window < 1:
        raise InputError(f"--window must be >= 1, got {args.window}")
    node = cli_node()
    try:
        type_name, qos = wait_for_publisher(node, args.topic, args.timeout)
        if not type_name:
            return 0
        stamps: deque[int] = deque(maxlen=args.window + 1)
        clock = node.get_clock()
        node.create_subscription(
            type_name, names.resolve_topic(args.topic),
            lambda data, info: stamps.append(clock.now().nanoseconds), qos, raw=True,
        )
        start = last = time.monotonic()
        while api.ok():
            node.spin_once(0.05)
            now = time.monotonic()
            if now - last >= 1.0:
                last = now
                report = rate_report(stamps)
                print(report or "no new messages", flush=True)
            if args.duration is not None and now - start >= args.duration:
                break
    finally:
        node.destroy_node()
    return 0
