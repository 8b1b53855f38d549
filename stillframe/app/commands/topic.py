"""``stillframe topic list|info|echo|hz|pub``: ROS 2 topics without ROS, shaped like ``ros2 topic``.

``list`` and ``info`` read the graph from the graph daemon (:mod:`stillframe.app.graph_daemon`,
started on demand; ``--no-daemon`` asks a node of this process, once discovery has settled).
A topic name that matches nothing is one line naming the closest existing topics.
"""

from __future__ import annotations

import argparse
import time
from collections import deque
from typing import Any

from stillframe.app.arguments import seconds
from stillframe.app.ros_tools import (
    add_strategy_arguments,
    add_verbs,
    existing_topic,
    graph_of,
    tool_node,
)
from stillframe.errors import InputError
from stillframe.middleware.graph import did_you_mean

QOS_PROFILES = ("default", "sensor_data", "clock", "parameters")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe topic`` and its verbs (``echo``, ``hz``, ``info``, ``list``, ``pub``) to
    ``sub``, each verb with its ``run_VERB`` as its action."""
    verbs = add_verbs(sub, "topic", "list, inspect, echo, measure and publish ROS 2 topics (like "
                                    "ros2 topic)")

    listing = verbs.add_parser("list", help="topics seen on the network")
    listing.add_argument("-t", "--show-types", action="store_true", help="also print types")
    listing.add_argument("-c", "--count-topics", action="store_true",
                         help="only print the number of topics")
    listing.add_argument("--include-hidden-topics", action="store_true",
                         help="also list hidden topics (a token starting with '_': the monitor "
                              "taps under /_monitor)")
    add_strategy_arguments(listing)
    listing.set_defaults(func=run_list)

    info = verbs.add_parser("info", help="a topic's type and its publishers and subscriptions")
    info.add_argument("topic", metavar="TOPIC")
    info.add_argument("-v", "--verbose", action="store_true",
                      help="each endpoint's node, type, type hash, GID and QoS")
    add_strategy_arguments(info)
    info.set_defaults(func=run_info)

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

    pub = verbs.add_parser("pub", help="publish a message given as YAML")
    pub.add_argument("topic", metavar="TOPIC")
    pub.add_argument("type", metavar="TYPE", help="e.g. std_msgs/msg/Float64")
    pub.add_argument("values", metavar="VALUES", nargs="?", default="{}",
                     help="the fields as YAML, e.g. 'data: 0.5' (default: all zero)")
    pub.add_argument("-r", "--rate", type=float, default=1.0, metavar="N",
                     help="publishing rate in Hz (default 1)")
    times = pub.add_mutually_exclusive_group()
    times.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    times.add_argument("-t", "--times", type=int, default=0, metavar="N",
                       help="publish N messages and exit (default: until Ctrl-C)")
    pub.add_argument("-p", "--print", type=int, default=1, metavar="N", dest="print_nth",
                     help="print only every N-th message (0: none; default 1)")
    pub.add_argument("-w", "--wait-matching-subscriptions", type=int, default=None, metavar="N",
                     help="wait for N matching subscriptions first (default 1 with --once or "
                          "--times, else 0)")
    pub.add_argument("--max-wait-time-secs", type=float, default=None, metavar="S",
                     help="give up waiting for subscriptions after S seconds (exit 2)")
    pub.add_argument("--keep-alive", type=float, default=0.1, metavar="S",
                     help="stay in the graph S seconds after the last message (default 0.1)")
    pub.add_argument("--qos-profile", choices=QOS_PROFILES, default="default",
                     help="QoS profile (default: default, reliable keep-last 10)")
    pub.add_argument("--qos-reliability", choices=("reliable", "best_effort"),
                     help="override the profile's reliability")
    pub.add_argument("--qos-durability", choices=("volatile", "transient_local"),
                     help="override the profile's durability")
    pub.set_defaults(func=run_pub)


def add_wait_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--timeout S`` to ``parser``: give up when no publisher of the topic appears within S
    seconds (default: wait for one)."""
    parser.add_argument("--timeout", type=float, metavar="S",
                        help="give up if no publisher appears within S seconds (default: wait)")


def run_list(args: argparse.Namespace) -> int:
    """``topic list``: the topics of the graph, one a line (``--show-types``: with their types;
    ``--count-topics``: how many); exit code 0."""
    graph = graph_of(args)
    topics = [(t, types) for t, types in graph.get_topic_names_and_types()
              if t in set(graph.topic_names(args.include_hidden_topics))]
    if args.count_topics:
        print(len(topics))
        return 0
    for topic, types in topics:
        print(f"{topic} [{', '.join(types)}]" if args.show_types else topic)
    return 0


def run_info(args: argparse.Namespace) -> int:
    """``topic info TOPIC``: its type and the counts of publishers and subscriptions (``--verbose``:
    each endpoint with its node, GID and QoS); exit code 0."""
    graph = graph_of(args)
    topic = existing_topic(graph, args.topic)
    types = dict(graph.get_topic_names_and_types())[topic]
    end = "\n\n" if args.verbose else "\n"
    print(f"Type: {types[0] if len(types) == 1 else types}", end=end)
    for label, endpoints in (("Publisher", graph.get_publishers_info_by_topic(topic)),
                             ("Subscription", graph.get_subscriptions_info_by_topic(topic))):
        print(f"{label} count: {len(endpoints)}", end=end)
        if args.verbose:
            for endpoint in endpoints:
                print(endpoint.describe(), end=end)
    return 0


def check_published_or_new(full: str) -> bool | None:
    """Whether the daemon's settled graph shows a publisher of ``full`` (asked when this
    process's node found none at once; None without the daemon). A name that matches no topic
    of that graph while close names exist is a misspelling: one line naming them (exit 2)
    instead of waiting for a publisher that will never come. A name with no close one may be a
    topic still to come: the caller waits for it, as ``ros2 topic echo`` does."""
    from stillframe.app import graph_daemon

    graph = graph_daemon.graph()
    if graph is None:
        return None
    known = graph.topic_names(include_hidden=True)
    if full not in known and (hint := did_you_mean(full, known)):
        raise InputError(f"topic {full} does not exist{hint}")
    return bool(graph.get_publishers_info_by_topic(full))


def run_echo(args: argparse.Namespace) -> int:
    """``topic echo TOPIC``: each message as YAML followed by ``---`` once a publisher appears
    (``--field``: one field; ``--once``: the first only); exit code 0."""
    from stillframe.middleware import api, names
    from stillframe.middleware.monitor import select_field, to_yaml, wait_for_publisher

    node = tool_node("topic")
    try:
        type_name, qos = wait_for_publisher(node, args.topic, args.timeout,
                                            on_missing=check_published_or_new)
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


def hz_line(stamps: deque[int], reported: int) -> str:
    """What ``topic hz`` prints each second: the statistics, or ``no new messages`` when none
    arrived since the last report (``reported``: the newest receive time then), as ``ros2 topic
    hz`` does, instead of repeating stale figures."""
    from stillframe.middleware.monitor import rate_report

    report = rate_report(stamps) if stamps and stamps[-1] != reported else None
    return report or "no new messages"


def run_hz(args: argparse.Namespace) -> int:
    """``topic hz TOPIC``: the rate of arrival over the last ``--window`` samples, printed about
    once a second as ``ros2 topic hz`` prints it; exit code 0."""
    if args.window < 1:
        raise InputError(f"--window must be >= 1, got {args.window}")
    from stillframe.middleware import api, names
    from stillframe.middleware.monitor import wait_for_publisher

    node = tool_node("topic")
    try:
        type_name, qos = wait_for_publisher(node, args.topic, args.timeout,
                                            on_missing=check_published_or_new)
        if not type_name:
            return 0
        stamps: deque[int] = deque(maxlen=args.window + 1)
        clock = node.get_clock()
        node.create_subscription(
            type_name, names.resolve_topic(args.topic),
            lambda data, info: stamps.append(clock.now().nanoseconds), qos, raw=True,
        )
        reported = 0
        start = last = time.monotonic()
        while api.ok():
            node.spin_once(0.05)
            now = time.monotonic()
            if now - last >= 1.0:
                last = now
                print(hz_line(stamps, reported), flush=True)
                reported = stamps[-1] if stamps else 0
            if args.duration is not None and now - start >= args.duration:
                break
    finally:
        node.destroy_node()
    return 0


def message_repr(msg: Any) -> str:
    """rclpy's ``repr`` of a message: ``std_msgs.msg.Float64(data=0.5)``."""
    from stillframe.contract import messages

    kind = getattr(msg, "__msgtype__", None)
    if kind is None:
        return repr(msg.tolist() if hasattr(msg, "tolist") else msg)
    fields = ", ".join(f"{f}={message_repr(getattr(msg, f))}" for f, _ in messages.fielddefs(kind))
    return f"{kind.replace('/', '.')}({fields})"


def pub_qos(args: argparse.Namespace) -> Any:
    """The QoS of ``topic pub``: the profile ``--qos-profile`` with ``--qos-reliability`` and
    ``--qos-durability`` applied."""
    from dataclasses import replace

    from stillframe.middleware.qos import PROFILES, Durability, Reliability

    qos = PROFILES[args.qos_profile]
    if args.qos_reliability:
        qos = replace(qos, reliability=Reliability[args.qos_reliability.upper()])
    if args.qos_durability:
        qos = replace(qos, durability=Durability[args.qos_durability.upper()])
    return qos


def run_pub(args: argparse.Namespace) -> int:
    """``topic pub TOPIC TYPE VALUES``: publish the message given as YAML at ``--rate`` Hz,
    ``--times`` times (0: until Ctrl-C) or ``--once``; exit code 0."""
    import yaml

    from stillframe.config.yamlio import load_yaml
    from stillframe.contract import messages
    from stillframe.contract.message_yaml import from_yaml
    from stillframe.middleware import api, names

    if not args.rate > 0:
        raise InputError(f"--rate must be > 0, got {args.rate:g}")
    if args.times < 0:
        raise InputError(f"--times must be >= 0, got {args.times}")
    times = 1 if args.once else args.times
    wanted = (args.wait_matching_subscriptions if args.wait_matching_subscriptions is not None
              else int(times != 0))
    topic = names.resolve_topic(args.topic)
    known = sorted(t for t in messages.TYPESTORE.fielddefs if "/msg/" in t)
    if args.type not in known:
        raise InputError(f"unknown message type {args.type}{did_you_mean(args.type, known)}")
    type_name = args.type
    try:
        values = load_yaml(args.values)
    except yaml.YAMLError as exc:
        raise InputError(f"VALUES {args.values!r}: not valid YAML ({type(exc).__name__})") from None
    stampers: list[Any] = []
    msg = from_yaml(type_name, values, stampers=stampers)
    node = tool_node("topic_pub")
    try:
        pub = node.create_publisher(type_name, topic, pub_qos(args))
        waited = 0.0
        while pub.get_subscription_count() < wanted and api.ok():
            if waited == 0.0:
                print(f"Waiting for at least {wanted} matching subscription(s)...", flush=True)
            if args.max_wait_time_secs is not None and waited >= args.max_wait_time_secs:
                raise InputError(f"timed out waiting for subscribers: expected {wanted}, got "
                                 f"{pub.get_subscription_count()}")
            node.spin_once(0.1)
            waited += 0.1
        print("publisher: beginning loop", flush=True)
        count = 0

        def publish() -> None:
            nonlocal count
            now = node.get_clock().now().nanoseconds
            for stamp in stampers:
                stamp(now)
            count += 1
            if args.print_nth and count % args.print_nth == 0:
                print(f"publishing #{count}: {message_repr(msg)}\n", flush=True)
            pub.publish(msg)

        publish()
        if times != 1:
            node.create_timer(1.0 / args.rate, publish)
            while api.ok() and (times == 0 or count < times):
                node.spin_once(None)
        pub.wait_for_all_acked(max(args.keep_alive, 1.0))
        time.sleep(args.keep_alive)
    finally:
        node.destroy_node()
    return 0
