"""``stillframe bag info DIR [--json]``: what ``ros2 bag info`` shows about a rosbag2 bag, its
checksums and its metadata checked against its storage files (what is damaged or disagrees:
one line, exit code 3, after the information; samples the recorder counted missing: a warning).
``stillframe bag reindex DIR [--json]``: recover a bag whose recorder was killed or whose file
was cut or damaged: every whole, intact message (:mod:`stillframe.bags.reindex`)."""

from __future__ import annotations

import argparse
import json
import sys

from stillframe.app.arguments import add_json_argument, emit_json
from stillframe.text_table import format_table


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe bag`` and its verbs (``info``, ``reindex``) to ``sub``, each verb with its
    ``run_VERB`` as its action."""
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
    """``bag info DIR``: the bag's summary (``--json``: as a document), a warning for samples the
    recorder counted missing; a :class:`~stillframe.errors.BagError` after the summary for what is
    damaged or disagrees."""
    from stillframe.bags.storage import bag_summary, format_summary
    from stillframe.contract.messages import TYPESTORE
    from stillframe.errors import BagError

    summary = bag_summary(args.bag, TYPESTORE)
    if args.json:
        emit_json(summary.as_dict())
    else:
        print(format_summary(summary))
    if missing := recorded_missing(summary.custom_data):
        print(f"stillframe bag info: warning: the recorder found {sum(missing.values())} "
              "samples missing from their topics' stamp grids: "
              + ", ".join(f"{t} {n}" for t, n in missing.items()), file=sys.stderr)
    if summary.problems:
        raise BagError("; ".join(summary.problems))
    return 0


def recorded_missing(custom_data: dict[str, str]) -> dict[str, int]:
    """The samples the recorder counted missing per topic (its ``custom_data``), those with
    any; empty when it counted none or the bag is not one of its."""
    from stillframe.recording.recorder import MISSING_KEY

    try:
        counted = json.loads(custom_data.get(MISSING_KEY, "{}"))
        return {str(t): int(n) for t, n in counted.items() if int(n) > 0}
    except (ValueError, TypeError, AttributeError):
        return {}


def run_reindex(args: argparse.Namespace) -> int:
    """Exit code 0 when every whole message was kept (a complete bag, or a cut one: what a
    killed recorder leaves), 3 when something was damaged or dropped (said on stderr)."""
    from stillframe.bags.reindex import reindex
    from stillframe.contract.messages import TYPESTORE
    from stillframe.errors import BagError

    result = reindex(args.bag, TYPESTORE)
    damaged = bool(result.dropped or result.problems) or (
        result.indexed is not None and result.total < result.indexed)
    if args.json:
        emit_json({"bag": str(result.path), "state": result.state, "complete": result.complete,
                   "truncated": result.truncated, "messages": result.total,
                   "topics": result.counts, "from_partial_chunk": result.from_partial_chunk,
                   "dropped": result.dropped, "problems": result.problems,
                   "summary_counted": result.indexed})
    else:
        partial = (f" ({result.from_partial_chunk} from the chunk it was cut in)"
                   if result.from_partial_chunk else "")
        counted = (f" of the {result.indexed} its summary counts"
                   if result.indexed is not None and result.indexed > result.total else "")
        print(f"{result.path}: {result.state}: {result.total} messages{counted}{partial}")
        print(format_table(["topic", "messages"], [[t, n] for t, n in result.counts.items()]))
    for reason, count in result.dropped.items():
        print(f"{result.path}: dropped {count} ({reason.replace('_', ' ')})", file=sys.stderr)
    if damaged:
        raise BagError(f"{result.path}: {result.state}: " + "; ".join(
            result.problems or [f"dropped {n} ({r.replace('_', ' ')})"
                                for r, n in result.dropped.items()] or ["summary counted more"]))
    return 0
