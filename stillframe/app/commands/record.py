"""``stillframe record -o DIR (--all | TOPIC...)``: record topics into a rosbag2 bag (MCAP).

Its last lines say how many messages it wrote per topic and, as a warning, what the bag misses
(samples missing from their topics' stamp grids, stalls of the recorder:
:mod:`stillframe.recording.recorder`); the exit code stays 0 then, as ``ros2 bag record``'s."""

from __future__ import annotations

import argparse
import sys

from stillframe.app.arguments import add_priority_arguments
from stillframe.files import check_output


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe record``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser(
        "record", help="record topics into a rosbag2 bag (metadata v9, MCAP), like ros2 bag record",
        description="Record until Ctrl-C (SIGINT) or SIGTERM; the bag is closed cleanly then.")
    parser.add_argument("-o", "--output", required=True, metavar="DIR",
                        help="bag directory to create (must not exist)")
    parser.add_argument("-a", "--all", action="store_true", help="record every topic")
    parser.add_argument("topics", nargs="*", metavar="TOPIC", help="topics to record")
    parser.add_argument("--use-sim-time", action="store_true",
                        help="stamp messages with the time on /clock instead of the system time")
    parser.add_argument("--node-name", default=None, metavar="NAME",
                        help="the recorder's node name, as ros2 bag record's (default: "
                             "stillframe_recorder, the name a launch's simulator waits for)")
    add_priority_arguments(parser, nice=0, who="recorder")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Record until Ctrl-C and print the messages written per topic and what the bag misses; exit
    code 0."""
    from stillframe.bags.storage import BagWriter
    from stillframe.contract import messages
    from stillframe.errors import InputError
    from stillframe.middleware.api import create_node, spin
    from stillframe.middleware.names import resolve_topic, validate_node_name
    from stillframe.node_runtime.realtime import run_idle, run_nicer
    from stillframe.node_runtime.support import RECORDER_NODE
    from stillframe.recording.recorder import Recorder

    check_output("-o", args.output, folder=True)

    if args.all == bool(args.topics):
        raise InputError("give either --all or one or more TOPICs")
    topics = [resolve_topic(t) for t in args.topics]
    name = RECORDER_NODE if args.node_name is None else validate_node_name(args.node_name)
    # the niceness before the middleware starts its threads (they inherit it); SCHED_IDLE only
    # once the bag is open and the readers exist, so that a busy machine, which leaves an idle
    # process next to no CPU time, cannot hold the start (a launch waits for the line below
    # before it starts the loop), and back off it on the stop, to close the bag
    run_nicer(args.nice)
    # the node stays on system time: the recorder stamps on /clock itself (recording.recorder)
    node = create_node(name, argv=sys.argv[:1])
    try:
        with BagWriter(args.output, messages.TYPESTORE) as bag:
            recorder = Recorder(node, bag, topics, sim_time=args.use_sim_time)
            if args.idle:
                run_idle()
            node.get_logger().info(f"Recording to '{args.output}' "
                                   f"({'all topics' if args.all else ', '.join(topics)})")
            try:
                spin(node)
            finally:
                if args.idle:
                    run_idle(False)
            recorder.drain()
            recorder.write_losses()
        for topic in recorder.missing():
            node.get_logger().warning(f"no publisher on '{topic}' was seen: not recorded")
        per_topic = ", ".join(f"{t} {n}" for t, n in recorder.counts().items())
        node.get_logger().info(f"Recorded {recorder.total} messages"
                               + (f": {per_topic}" if per_topic else ""))
        if incomplete := recorder.summary():
            node.get_logger().warning(f"the bag {incomplete} (in "
                                      f"{args.output}/metadata.yaml, custom_data)")
    finally:
        node.destroy_node()
    return 0
