"""What the ``ros2``-like verbs share (``topic``, ``node``, ``param``): the graph from the daemon
or from a node of their own (``--no-daemon``, ros2cli's ``NodeStrategy``), a quiet tool node
(no backend banner unless ``stillframe --verbose``), and topic and node names checked against
the graph with the closest existing names suggested."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from stillframe.config.environment import check_environment, value
from stillframe.contract.topics import DEFAULT_NAMESPACE
from stillframe.errors import InputError
from stillframe.middleware import names
from stillframe.middleware.graph import SETTLE_LIMIT_S, Graph, did_you_mean

#: where ``stillframe --verbose`` is recorded for the tool nodes of this process
VERBOSE_ENV = "STILLFRAME_VERBOSE"


def add_verbs(sub: argparse._SubParsersAction, command: str, text: str,
              ) -> argparse._SubParsersAction:
    """The parser of a command of verbs (``topic list``, ``node info``, ...): its verbs, one
    required, in ``args.verb``."""
    verbs = sub.add_parser(command, help=text).add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    return verbs


def add_strategy_arguments(parser: argparse.ArgumentParser) -> None:
    """``--no-daemon`` and ``--spin-time``, as ros2cli's verbs that read the graph have them."""
    parser.add_argument("--no-daemon", action="store_true",
                        help="do not start nor use the graph daemon (stillframe daemon)")
    parser.add_argument("--spin-time", type=float, default=SETTLE_LIMIT_S, metavar="S",
                        help="without the daemon: wait at most S seconds for discovery to settle "
                             f"(default {SETTLE_LIMIT_S:g}; it usually settles well before)")


def tool_node(kind: str, verbose: bool | None = None) -> Any:
    """A hidden node for a command-line tool; it logs its backend only with ``--verbose``."""
    from stillframe.middleware import api

    check_environment()
    verbose = value(VERBOSE_ENV) == "1" if verbose is None else verbose
    quiet = [] if verbose else ["--ros-args", "--log-level", "warn"]
    return api.create_node(f"_stillframe_{kind}_{os.getpid()}", argv=["stillframe", *quiet])


def direct_graph(spin_time: float) -> Graph:
    """The graph seen by a node of this process, once discovery has settled."""
    from stillframe.middleware.graph import settle, snapshot

    node = tool_node("graph")
    try:
        settle_s, settled = settle(node, limit_s=spin_time)
        found = snapshot(node)
    finally:
        node.destroy_node()
    found.settle_s, found.settled = settle_s, settled
    return found


def graph_of(args: argparse.Namespace) -> Graph:
    """The graph for a verb: the daemon's (started on demand) unless ``--no-daemon``; a node of
    this process if the daemon cannot be reached."""
    check_environment()
    spin_time = getattr(args, "spin_time", SETTLE_LIMIT_S)
    if not spin_time > 0:
        raise InputError(f"--spin-time must be > 0, got {spin_time:g}")
    found = None
    if not getattr(args, "no_daemon", False):
        from stillframe.app import graph_daemon

        found = graph_daemon.graph()
    if found is None:
        found = direct_graph(spin_time)
    if not found.settled:
        print(f"WARNING: discovery had not settled after {found.settle_s:.1f} s: the graph was "
              "still changing, so this answer may be incomplete", file=sys.stderr)
    return found


def existing_topic(graph: Graph, topic: str) -> str:
    """``topic`` fully qualified if the graph has it; else InputError with the closest names."""
    full = names.resolve_topic(topic)
    known = graph.topic_names(include_hidden=True)
    if full not in known:
        raise InputError(f"unknown topic {full}{did_you_mean(full, known)}")
    return full


def node_name(text: str) -> str:
    """The fully qualified node name of NODE (a bare name is in the loop's namespace)."""
    full = text if text.startswith("/") else f"{DEFAULT_NAMESPACE}/{text}"
    namespace, _, name = full.rpartition("/")
    names.validate_node_name(name)
    names.validate_namespace(namespace or "/")
    return full


def existing_node(graph: Graph, text: str) -> str:
    """NODE fully qualified if it is in the graph (a bare name in the loop's namespace, else in
    the root namespace as ros2 takes it); else InputError with the closest names."""
    full = node_name(text)
    known = graph.node_names(include_hidden=True)
    for candidate in (full, *(() if text.startswith("/") else (f"/{text}",))):
        if candidate in known:
            return candidate
    raise InputError(f"node {full} not found{did_you_mean(full, known)}")
