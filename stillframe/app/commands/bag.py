"""``stillframe bag info DIR [--json]``: what ``ros2 bag info`` shows about a rosbag2 bag.
``stillframe bag reindex DIR [--json]``: recover a bag whose recorder was killed or whose file
was cut: every whole message before the cut (:mod:`stillframe.bags.reindex`)."""

from __future__ import annotations

import argparse
import sys

from stillframe.app.commands.common import add_json_argument, emit_json
from stillframe.text_table import format_table


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("bag", help="inspect rosbag2 bags")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    info = verbs.add_parser("info", help="duration, start, end, messages and topics of a bag")
    info.add_argument("bag", metavar="DIR", help="rosbag2 directory (metadata.yaml + .mcap/.db3)")
    add_json_argument(info)
    info.set_defaults(func=run_info)
    again = verbs.add_parser("reindex", help="recover a bag whose recorder was killed or whose "
                             "file was cut (like ros2 bag reindex): keeps every whole message")
    again.add_argument("bag", metavar="DIR", help="rosbag2 directory with one .mcap file")
    add_json_argument(again)
    again.set_defaults(func=run_reindex)


def run_info(args: argparse.Namespace) -> int:
    from stillframe.bags.storage import bag_summary, format_summary
    from stillframe.contract.messages import TYPESTORE

    summary = bag_summary(args.bag, TYPESTORE)
    if args.json:
        emit_json(summary.as_dict())
    else:
        print(format_summary(summary))
    return 0


def run_reindex(args: argparse.Namespace) -> int:
    from stillframe.bags.reindex import reindex
    from stillframe.contract.messages import TYPESTORE

    result = reindex(args.bag, TYPESTORE)
    if args.json:
        emit_json({"bag": str(result.path), "truncated": result.truncated,
                   "messages": result.total, "topics": result.counts,
                   "from_partial_chunk": result.from_partial_chunk, "dropped": result.dropped})
        return 0
    state = ("cut short; kept every whole message" if result.truncated else "complete")
    partial = (f" ({result.from_partial_chunk} from the chunk it was cut in)"
               if result.from_partial_chunk else "")
    print(f"{result.path}: {state}: {result.total} messages{partial}")
    for reason, count in result.dropped.items():
        print(f"{result.path}: dropped {count} ({reason.replace('_', ' ')})", file=sys.stderr)
    print(format_table(["topic", "messages"], [[t, n] for t, n in result.counts.items()]))
    return 0
