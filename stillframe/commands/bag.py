"""``stillframe bag info DIR [--json]``: what ``ros2 bag info`` shows about a rosbag2 bag."""

from __future__ import annotations

import argparse

from stillframe.commands.common import add_json_argument, emit_json


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("bag", help="inspect rosbag2 bags")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    info = verbs.add_parser("info", help="duration, start, end, messages and topics of a bag")
    info.add_argument("bag", metavar="DIR", help="rosbag2 directory (metadata.yaml + .mcap/.db3)")
    add_json_argument(info)
    info.set_defaults(func=run_info)


def run_info(args: argparse.Namespace) -> int:
    from stillframe.bags import bag_summary, format_summary
    from stillframe.messages import TYPESTORE

    summary = bag_summary(args.bag, TYPESTORE)
    if args.json:
        emit_json(summary.as_dict())
    else:
        print(format_summary(summary))
    return 0
