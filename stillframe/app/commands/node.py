"""``stillframe node list|info``: the nodes of the ROS graph, shaped like ``ros2 node``.

Both read the graph daemon's graph (``--no-daemon``: a node of this process, once discovery has
settled). Hidden nodes (a name starting with '_': the tools' own, the daemon) and hidden topics
are shown only when asked for, as ros2 does.
"""

from __future__ import annotations

import argparse
import sys

from stillframe.app.ros_tools import add_strategy_arguments, add_verbs, existing_node, graph_of
from stillframe.middleware import names
from stillframe.middleware.graph import Graph


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe node`` and its verbs (``info``, ``list``) to ``sub``, each verb with its
    ``run_VERB`` as its action."""
    verbs = add_verbs(sub, "node", "list nodes and show a node's topics and services (like ros2 "
                                   "node)")
    listing = verbs.add_parser("list", help="the nodes in the graph")
    listing.add_argument("-a", "--all", action="store_true", help="also hidden nodes")
    listing.add_argument("-c", "--count-nodes", action="store_true",
                         help="only print the number of nodes")
    add_strategy_arguments(listing)
    listing.set_defaults(func=run_list)
    info = verbs.add_parser("info", help="a node's publishers, subscribers and services")
    info.add_argument("node", metavar="NODE", help="e.g. /frame/sim_node (a bare name is in "
                                                   "/frame, else in /)")
    info.add_argument("--include-hidden", action="store_true",
                      help="also hidden topics and services")
    add_strategy_arguments(info)
    info.set_defaults(func=run_info)


def run_list(args: argparse.Namespace) -> int:
    """``node list``: the node names, one a line (``--count-nodes``: how many); exit code 0."""
    nodes = graph_of(args).node_names(include_hidden=args.all)
    if args.count_nodes:
        print(len(nodes))
    elif nodes:
        print(*nodes, sep="\n")
    return 0


def topics_of(graph: Graph, node: str, kind: str) -> list[tuple[str, list[str]]]:
    """(topic, types) of the node's endpoints of ``kind``, sorted by topic."""
    found: dict[str, set[str]] = {}
    for e in graph.endpoints:
        if e.node == node and e.kind == kind:
            found.setdefault(e.topic_name, set()).add(e.topic_type)
    return [(topic, sorted(types)) for topic, types in sorted(found.items())]


def services_of(graph: Graph, node: str, server: bool) -> list[tuple[str, list[str]]]:
    """The services ``node`` serves (``server``) or calls in ``graph``, sorted, with their types."""
    return sorted((s.name, list(s.types)) for s in graph.services
                  if s.node == node and s.server == server)


def run_info(args: argparse.Namespace) -> int:
    """``node info NODE``: what ``ros2 node info`` prints: the node's subscribers, publishers,
    service servers and clients with their types; exit code 0."""
    graph = graph_of(args)
    node = existing_node(graph, args.node)
    if (count := graph.node_names(include_hidden=True).count(node)) > 1:
        print(f"There are {count} nodes in the graph with the exact name \"{node}\". You are "
              "seeing information about only one of them.", file=sys.stderr)
    servers = services_of(graph, node, server=True)
    sections = [
        ("Subscribers", topics_of(graph, node, "SUBSCRIPTION")),
        ("Publishers", topics_of(graph, node, "PUBLISHER")),
        ("Service Servers", [s for s in servers if "/_action/" not in s[0]]),
        ("Service Clients", services_of(graph, node, server=False)),
        ("Action Servers", []),
        ("Action Clients", []),
    ]
    print(node)
    for title, entries in sections:
        print(f"  {title}:")
        shown = [f"    {name}: {', '.join(types)}" for name, types in entries
                 if args.include_hidden or not names.is_hidden(name)]
        print(*shown, sep="\n")
    return 0
