"""``stillframe param list|get|set|describe|dump|load``: a running node's parameters through the
standard parameter services (``rcl_interfaces/srv/ListParameters``, ``GetParameters``,
``SetParameters``, ``DescribeParameters`` under ``NODE/``), like ``ros2 param``.

``param list`` without NODE lists every node's parameter names as ``ros2 param list`` does
(``/node:`` then the names); nodes on the other DDS vendor than this process's backend are named
and skipped (parameter services do not cross vendors, docs/middleware.md). ``param describe``
prints what ``ros2 param describe`` prints (type, description, constraints: read-only, the range,
the constraints a range cannot say). ``param dump NODE`` prints the node's parameters as a ROS 2
parameter file; ``param load NODE FILE`` sets those a parameter file gives the node, one line per
parameter: the entries keyed ``/**`` (unless ``--no-use-wildcard``), by a pattern or the fully
qualified name that matches the node, or by its bare name (``controller_node:``, which ``ros2
param load`` takes too); a file that gives the node nothing is refused, naming its keys.

On the ``rclpy`` backend the calls go through rclpy's service clients, on ``dds`` through
:mod:`stillframe.middleware.dds_services`. NODE is a fully qualified name (``/frame/sim_node``)
or a bare name in the loop's namespace (``controller_node`` is ``/frame/controller_node``).
VALUE is parsed as YAML like ``-p NAME:=VALUE``; an integer for a double parameter is sent as a
double. A name the node does not declare is one line naming its closest parameters (exit 2); a
refused set prints the node's reason and exits 1. A node that does not answer is one line (exit
2) saying why where the graph shows it: on the other DDS vendor, or not there at all.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import yaml

from stillframe.app.arguments import add_json_argument, emit_json
from stillframe.app.ros_tools import (
    add_strategy_arguments,
    add_verbs,
    graph_of,
    node_name,
    tool_node,
)
from stillframe.config import environment
from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.middleware import api
from stillframe.middleware.graph import VENDORS, fqn, settle, suggest
from stillframe.middleware.param_messages import (
    DOUBLE,
    DOUBLE_ARRAY,
    INT64,
    NOT_SET,
    TYPE_NAMES,
    value_msg,
    value_of,
)
from stillframe.middleware.params import (
    WILDCARD,
    key_matches,
    param_file_entries,
    parse_value,
    resolve_entries,
)
from stillframe.text_table import format_table

SERVICE_TYPES = {"list": "ListParameters", "get": "GetParameters", "set": "SetParameters",
                 "describe": "DescribeParameters"}


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe param``, its arguments and :func:`run` as its action to ``sub``."""
    verbs = add_verbs(sub, "param", "list, get and set a running node's parameters (like ros2 "
                                    "param)")
    for verb, text in (("list", "every parameter with its type, value and read-only flag "
                                "(without NODE: every node's parameter names)"),
                       ("get", "one parameter's value"), ("set", "set one parameter"),
                       ("describe", "parameters' descriptions, ranges and constraints"),
                       ("dump", "the node's parameters as a ROS 2 parameter file (YAML)"),
                       ("load", "set the parameters a ROS 2 parameter file gives the node")):
        command = verbs.add_parser(verb, help=text)
        command.add_argument("node", metavar="NODE", nargs="?" if verb == "list" else None,
                             help="e.g. /frame/controller_node")
        if verb in ("get", "set"):
            command.add_argument("name", metavar="NAME")
        if verb == "describe":
            command.add_argument("names", metavar="NAME", nargs="+")
        if verb == "set":
            command.add_argument("value", metavar="VALUE", help="YAML, e.g. 0.5, false, [1, 2]")
        if verb == "load":
            command.add_argument("file", metavar="FILE", type=Path, help="parameter file")
            command.add_argument("--no-use-wildcard", action="store_true",
                                 help="do not load the parameters under '/**' (as ros2 param "
                                      "load)")
        command.add_argument("--timeout", type=float, default=10.0, metavar="S",
                             help="wait at most S seconds for the node (default 10)")
        if verb == "list":
            add_strategy_arguments(command)
        if verb in ("list", "get", "set", "describe"):
            add_json_argument(command)
        command.set_defaults(func={"dump": run_dump, "load": run_load,
                                   "describe": run_describe}.get(verb, run))


class ParameterCalls:
    """The parameter services of one remote node, called from a hidden local node."""

    def __init__(self, node: api.Node, target: str, timeout_sec: float) -> None:
        self.node = node
        self.target = target
        self.timeout_sec = timeout_sec

    def call(self, verb: str, **fields: Any) -> Any:
        """Call the target's parameter service of ``verb`` (``list``, ``get``, ``set``,
        ``describe``) with the request ``fields`` and return the response; an
        :class:`~stillframe.errors.InputError` saying why when no answer comes within the
        timeout."""
        srv = SERVICE_TYPES[verb]
        request = messages.new(f"rcl_interfaces/srv/{srv}_Request", **fields)
        service = f"{self.target}/{verb}_parameters"
        response = self.node.call_service(f"rcl_interfaces/srv/{srv}", service, request,
                                          self.timeout_sec)
        if response is None:
            raise InputError(f"node {self.target}: no answer on {service} within "
                             f"{self.timeout_sec:g} s ({self.why_no_answer()})")
        return response

    def why_no_answer(self) -> str:
        """What the graph of this process says of the target: on another DDS vendor (parameter
        services do not cross vendors, docs/middleware.md), or not in the graph, once this
        process's view of the graph has settled (a node of the other vendor is named late)."""
        settle(self.node)
        namespace, _, name = self.target.rpartition("/")
        ours = BACKEND_VENDORS[self.node.backend]
        vendors = node_vendors(self.node, self.target)
        if vendors and ours not in vendors:
            other = next(b for b, v in BACKEND_VENDORS.items() if v in vendors)
            return (f"it runs on {', '.join(sorted(vendors))} and this client on {ours}, and "
                    "parameter services do not cross DDS vendors: run the call with "
                    f"STILLFRAME_RMW={other}")
        if (name, namespace or "/") in self.node.get_node_names_and_namespaces():
            other = next(b for b in BACKEND_VENDORS if b != self.node.backend)
            return ("it is in the graph but did not answer; if it runs on another DDS vendor "
                    f"than this client's {ours}, run the call with STILLFRAME_RMW={other}: "
                    "parameter services do not cross vendors")
        return (f"it is not in the graph: is it running, on ROS_DOMAIN_ID="
                f"{environment.value('ROS_DOMAIN_ID')}?")

    def declared(self, name: str) -> Any:
        """The ``ParameterValue`` of ``name``; InputError naming the node's closest parameters
        when it declares no such name (rclpy then answers no value, the dds backend NOT_SET)."""
        values = self.call("get", names=[name]).values
        if values and values[0].type != NOT_SET:
            return values[0]
        known = sorted(self.call("list").result.names)
        close = suggest(name, known)
        raise InputError(f"node {self.target} has no parameter {name!r} " + (
            f"(did you mean {', '.join(close)}?)" if close else
            f"(its parameters: {', '.join(known) or 'none'})"))

    def describe(self, names_: list[str]) -> list[dict[str, Any]]:
        """name, type, value, read_only of each parameter (value None when not declared)."""
        values = self.call("get", names=names_).values
        descriptors = self.call("describe", names=names_).descriptors
        return [{"name": n, "type": TYPE_NAMES.get(v.type, str(v.type)), "value": value_of(v),
                 "read_only": bool(d.read_only)}
                for n, v, d in zip(names_, values, descriptors, strict=True)]


#: the DDS vendor of each backend's participants (endpoint GUIDs carry the vendor's id)
BACKEND_VENDORS = {"rclpy": "Fast DDS", "dds": "Cyclone DDS"}


def node_vendors(node: api.Node, target: str) -> set[str]:
    """The DDS vendors of ``target``'s topic endpoints in ``node``'s graph (from their GUIDs)."""
    found = set()
    for topic, _ in node.get_topic_names_and_types():
        for info in (*node.get_publishers_info_by_topic(topic),
                     *node.get_subscriptions_info_by_topic(topic)):
            if fqn(info.node_namespace, info.node_name) == target:
                found.add(VENDORS.get(bytes(info.endpoint_gid[:2]), ""))
    return found - {""}


def value_for(current: Any, value: Any) -> Any:
    """``value`` as a double (array) when the parameter is one and ``value`` is an integer."""
    if current.type == DOUBLE and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if current.type == DOUBLE_ARRAY and isinstance(value, list) and all(
            isinstance(v, int) and not isinstance(v, bool) for v in value):
        return [float(v) for v in value]
    return value


def run(args: argparse.Namespace) -> int:
    """Run the ``param`` verb on the remote node (``dump`` and ``load`` are :func:`run_dump` and
    :func:`run_load`); exit code 1 when the node refused a set (its reason on stderr), else 0."""
    if args.verb == "list" and args.node is None:
        return list_all(args)
    target = node_name(args.node)
    if args.verb == "set":
        value = parse_value(args.value, f"VALUE of {args.name}")
    node = tool_node("param")
    try:
        calls = ParameterCalls(node, target, args.timeout)
        if args.verb == "list":
            return show(args, calls.describe(list(calls.call("list").result.names)))
        current = calls.declared(args.name)
        if args.verb == "get":
            return show(args, calls.describe([args.name]))
        value = value_for(current, value)
        parameter = messages.new("rcl_interfaces/msg/Parameter", name=args.name,
                                 value=value_msg(value))
        result = calls.call("set", parameters=[parameter]).results[0]
    finally:
        node.destroy_node()
    if args.json:
        emit_json({"node": target, "name": args.name, "successful": bool(result.successful),
                   "reason": result.reason})
    elif result.successful:
        print(f"set {target} {args.name} = {value}")
    if not result.successful:
        print(f"stillframe param: {target} refused {args.name}: {result.reason}",
              file=sys.stderr)
        return 1
    return 0


def show(args: argparse.Namespace, rows: list[dict[str, Any]]) -> int:
    """Print parameter ``rows``: as JSON with ``--json``, the bare value for ``get``, else a table
    of name, type, value and read-only; exit code 0."""
    if args.json:
        emit_json(rows if args.verb == "list" else rows[0])
    elif args.verb == "get":
        print(rows[0]["value"])
    else:
        print(format_table(["name", "type", "value", "read-only"],
                           [[r["name"], r["type"], r["value"], "yes" if r["read_only"] else ""]
                            for r in rows]))
    return 0


def descriptor_lines(descriptor: Any) -> list[str]:
    """What ``ros2 param describe`` prints of one descriptor (ros2param's ``describe`` verb)."""
    lines = [f"Parameter name: {descriptor.name}",
             f"  Type: {TYPE_NAMES.get(descriptor.type, str(descriptor.type))}"]
    if descriptor.description:
        lines.append(f"  Description: {descriptor.description}")
    lines.append("  Constraints:")
    if descriptor.read_only:
        lines.append("    Read only: true")
    ranges = [*descriptor.floating_point_range, *descriptor.integer_range]
    if ranges:
        lines += [f"    Min value: {ranges[0].from_value}", f"    Max value: {ranges[0].to_value}"]
        if ranges[0].step:
            lines.append(f"    Step: {ranges[0].step}")
    if descriptor.additional_constraints:
        lines.append(f"    Additional constraints: {descriptor.additional_constraints}")
    return lines


def descriptor_json(descriptor: Any) -> dict[str, Any]:
    """A descriptor for ``--json``: its range's bounds null where there is none (infinite, or
    an integer range's int64 limit)."""
    ranges = [*descriptor.floating_point_range, *descriptor.integer_range]

    def bound(value: float) -> float | None:
        return None if value in INT64 or not math.isfinite(value) else value

    return {"name": descriptor.name, "type": TYPE_NAMES.get(descriptor.type, ""),
            "description": descriptor.description,
            "additional_constraints": descriptor.additional_constraints,
            "read_only": bool(descriptor.read_only),
            "range": ({"from": bound(ranges[0].from_value), "to": bound(ranges[0].to_value),
                       "step": ranges[0].step} if ranges else None)}


def run_describe(args: argparse.Namespace) -> int:
    """``ros2 param describe NODE NAME...``: each parameter's descriptor as ros2 prints it; a
    name the node does not declare is one line naming the closest (exit 2)."""
    target = node_name(args.node)
    node = tool_node("param")
    try:
        calls = ParameterCalls(node, target, args.timeout)
        for name in args.names:
            calls.declared(name)
        descriptors = calls.call("describe", names=args.names).descriptors
    finally:
        node.destroy_node()
    if args.json:
        emit_json([descriptor_json(d) for d in descriptors])
    else:
        print("\n".join(line for d in descriptors for line in descriptor_lines(d)))
    return 0


def list_all(args: argparse.Namespace) -> int:
    """``ros2 param list`` without a node: ``/node:`` and its parameter names, for every node
    this process's vendor can reach."""
    graph = graph_of(args)
    node = tool_node("param")
    ours = BACKEND_VENDORS[node.backend]
    listed: dict[str, list[str]] = {}
    try:
        for target in graph.node_names():
            vendors = {e.vendor for e in graph.endpoints if e.node == target} - {""}
            if vendors and ours not in vendors:
                print(f"{target}: on {', '.join(sorted(vendors))}, not reachable from "
                      f"{ours} (STILLFRAME_RMW={'dds' if ours == 'Fast DDS' else 'rclpy'} "
                      f"reaches it)", file=sys.stderr)
                continue
            try:
                listed[target] = sorted(ParameterCalls(node, target, args.timeout)
                                        .call("list").result.names)
            except InputError as exc:
                print(f"{target}: {exc}", file=sys.stderr)
    finally:
        node.destroy_node()
    if args.json:
        emit_json(listed)
        return 0
    for target, parameter_names in listed.items():
        if parameter_names:
            print(f"{target}:")
            print(*(f"  {name}" for name in parameter_names), sep="\n")
    return 0


def nest(flat: dict[str, Any]) -> dict[str, Any]:
    """``{"a.b": 1}`` -> ``{"a": {"b": 1}}``, as ``ros2 param dump`` writes dotted names."""
    tree: dict[str, Any] = {}
    for name, value in flat.items():
        *parents, leaf = name.split(".")
        branch = tree
        for part in parents:
            branch = branch.setdefault(part, {})
        branch[leaf] = value
    return tree


def run_dump(args: argparse.Namespace) -> int:
    """``param dump NODE``: every parameter of the node as a params file (YAML, ``NODE:
    ros__parameters:``) on stdout; exit code 0."""
    target = node_name(args.node)
    node = tool_node("param")
    try:
        calls = ParameterCalls(node, target, args.timeout)
        parameter_names = sorted(calls.call("list").result.names)
        values = calls.call("get", names=parameter_names).values
    finally:
        node.destroy_node()
    flat = {n: value_of(v) for n, v in zip(parameter_names, values, strict=True)}
    print(yaml.dump({target: {"ros__parameters": nest(flat)}}, default_flow_style=False))
    return 0


def loaded(path: Path, target: str, *, wildcard: bool) -> dict[str, Any]:
    """The parameters a parameter file gives node ``target`` for ``param load``: the entries
    keyed ``/**`` (with ``wildcard``), by a pattern or the fully qualified name matching the
    node, or by its bare name (rcl reads a bare key as the root namespace's node; ``ros2 param
    load`` takes it, as it takes every key), a key naming the node winning over ``/**``.
    InputError naming the file's keys when none reaches the node: a load that sets nothing."""
    entries = param_file_entries(path)
    bare = target.rsplit("/", 1)[-1]
    mine = [(target if key == bare else key, values) for key, values in entries
            if (key == bare or key_matches(key, target)) and (wildcard or key != WILDCARD)]
    if not mine:
        keys = ", ".join(dict.fromkeys(key for key, _ in entries)) or "none"
        raise InputError(f"parameter file {path}: no entry for {target} (its keys: {keys}; "
                         f"give '{target}:', '{bare}:' or '{WILDCARD}:')")
    return resolve_entries(mine, target)


def run_load(args: argparse.Namespace) -> int:
    """``param load NODE FILE``: set the node's parameters from a params file, one line per
    parameter saying whether it was set; exit code 1 if any was refused, else 0."""
    target = node_name(args.node)
    wanted = loaded(args.file, target, wildcard=not args.no_use_wildcard)
    node = tool_node("param")
    try:
        calls = ParameterCalls(node, target, args.timeout)
        current = calls.call("get", names=list(wanted)).values
        parameters = [messages.new("rcl_interfaces/msg/Parameter", name=name,
                                   value=value_msg(value_for(now, value)))
                      for (name, value), now in zip(wanted.items(), current, strict=True)]
        results = calls.call("set", parameters=parameters).results if parameters else []
    finally:
        node.destroy_node()
    failed = 0
    for name, result in zip(wanted, results, strict=True):
        line = f"Set parameter {name} {'successful' if result.successful else 'failed'}"
        line += f": {result.reason}" if result.reason else ""
        print(line, file=sys.stdout if result.successful else sys.stderr)
        failed += not result.successful
    return 1 if failed else 0
