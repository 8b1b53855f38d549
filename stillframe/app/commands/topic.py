"""``stillframe topic list|echo|hz``: watch ROS 2 topics without ROS (like ``ros2 topic``)."""

from __future__ import annotations

import argparse
import time
from collections import deque
from typing import Any

from stillframe.app.commands.common import seconds
from stillframe.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("topic", help="list, echo and measure ROS 2 topics (like ros2 topic)")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True

    listing = verbs.add_parser("list", help="topics seen on the network")
    listing.add_argument("-t", "--show-types", action="store_true", help="also print types")
    listing.add_argument("--include-hidden-topics", action="store_true",
                         help="also list hidden topics (a token starting with '_': the monitor "
                              "taps under /_monitor)")
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
    hz.add_argument("--duration", type=seconds, metavar="S",
                    help="stop after S seconds (default: until Ctrl-C)")
    add_wait_argument(hz)
    hz.set_defaults(func=run_hz)


def add_wait_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--timeout", type=float, metavar="S",
                        help="give up if no publisher appears within S seconds (default: wait)")


def run_list(args: argparse.Namespace) -> int:
    from stillframe.middleware import api, names
    from stillframe.middleware.monitor import cli_node

    node = cli_node()
    try:
        deadline = time.monotonic() + args.spin_time
        while api.ok() and time.monotonic() < deadline:
            node.spin_once(0.05)
        for topic, types in node.get_topic_names_and_types():
            if names.is_hidden(topic) and not args.include_hidden_topics:
                continue
            print(f"{topic} [{', '.join(types)}]" if args.show_types else topic)
    finally:
        node.destroy_node()
    return 0


def run_echo(args: argparse.Namespace) -> int:
    from stillframe.middleware import api, names
    from stillframe.middleware.monitor import cli_node, select_field, to_yaml, wait_for_publisher

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


def run_hz(args: argparse.Namespace) -> int:
    if args.window < 1:
        raise InputError(f"--window must be >= 1, got {args.window}")
    from stillframe.middleware import api, names
    from stillframe.middleware.monitor import cli_node, rate_report, wait_for_publisher

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
