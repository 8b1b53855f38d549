"""``stillframe param list|get|set|dump|load``: a running node's parameters through the standard
parameter services (``rcl_interfaces/srv/ListParameters``, ``GetParameters``,
``SetParameters``, ``DescribeParameters`` under ``NODE/``), like ``ros2 param``.

``param list`` without NODE lists every node's parameter names as ``ros2 param list`` does
(``/node:`` then the names); nodes on the other DDS vendor than this process's backend are named
and skipped (parameter services do not cross vendors, docs/middleware.md). ``param dump NODE``
prints the node's parameters as a ROS 2 parameter file; ``param load NODE FILE`` sets those a
parameter file gives the node (its own key and the ``/**`` wildcard), one line per parameter.

On the ``rclpy`` backend the calls go through rclpy's service clients, on ``dds`` through
:mod:`stillframe.middleware.dds_services`. NODE is a fully qualified name (``/frame/sim_node``)
or a bare name in the loop's namespace (``controller_node`` is ``/frame/controller_node``).
VALUE is parsed as YAML like ``-p NAME:=VALUE``; an integer for a double parameter is sent as a
double. A refused set prints the node's reason and exits 1.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import yaml

from stillframe.app.commands.common import add_json_argument, emit_json
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
from stillframe.middleware.param_messages import (
    DOUBLE,
    DOUBLE_ARRAY,
    NOT_SET,
    TYPE_NAMES,
    value_msg,
    value_of,
)
from stillframe.middleware.params import load_param_file, parse_value
from stillframe.text_table import format_table

SERVICE_TYPES = {"list": "ListParameters", "get": "GetParameters", "set": "SetParameters",
                 "describe": "DescribeParameters"}


def register(sub: argparse._SubParsersAction) -> None:
    verbs = add_verbs(sub, "param", "list, get and set a running node's parameters (like ros2 "
                                    "param)")
    for verb, text in (("list", "every parameter with its type, value and read-only flag "
                                "(without NODE: every node's parameter names)"),
                       ("get", "one parameter's value"), ("set", "set one parameter"),
                       ("dump", "the node's parameters as a ROS 2 parameter file (YAML)"),
                       ("load", "set the parameters a ROS 2 parameter file gives the node")):
        command = verbs.add_parser(verb, help=text)
        command.add_argument("node", metavar="NODE", nargs="?" if verb == "list" else None,
                             help="e.g. /frame/controller_node")
        if verb in ("get", "set"):
            command.add_argument("name", metavar="NAME")
        if verb == "set":
            command.add_argument("value", metavar="VALUE", help="YAML, e.g. 0.5, false, [1, 2]")
        if verb == "load":
            command.add_argument("file", metavar="FILE", type=Path, help="parameter file")
        command.add_argument("--timeout", type=float, default=10.0, metavar="S",
                             help="wait at most S seconds for the node (default 10)")
        if verb == "list":
            add_strategy_arguments(command)
        if verb in ("list", "get", "set"):
            add_json_argument(command)
        command.set_defaults(func={"dump": run_dump, "load": run_load}.get(verb, run))


class ParameterCalls:
    """The parameter services of one remote node, called from a hidden local node."""

    def __init__(self, node: api.Node, target: str, timeout_sec: float) -> None:
        self.node = node
        self.target = target
        self.timeout_sec = timeout_sec

    def call(self, verb: str, **fields: Any) -> Any:
        srv = SERVICE_TYPES[verb]
        request = messages.new(f"rcl_interfaces/srv/{srv}_Request", **fields)
        service = f"{self.target}/{verb}_parameters"
        response = self.node.call_service(f"rcl_interfaces/srv/{srv}", service, request,
                                          self.timeout_sec)
        if response is None:
            raise InputError(
                f"node {self.target}: no answer on {service} within {self.timeout_sec:g} s "
                f"(is it running, on ROS_DOMAIN_ID={environment.value('ROS_DOMAIN_ID')}?)")
        return response

    def describe(self, names_: list[str]) -> list[dict[str, Any]]:
        """name, type, value, read_only of each parameter (value None when not declared)."""
        values = self.call("get", names=names_).values
        descriptors = self.call("describe", names=names_).descriptors
        return [{"name": n, "type": TYPE_NAMES.get(v.type, str(v.type)), "value": value_of(v),
                 "read_only": bool(d.read_only)}
                for n, v, d in zip(names_, values, descriptors, strict=True)]


def value_for(current: Any, value: Any) -> Any:
    """``value`` as a double (array) when the parameter is one and ``value`` is an integer."""
    if current.type == DOUBLE and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if current.type == DOUBLE_ARRAY and isinstance(value, list) and all(
            isinstance(v, int) and not isinstance(v, bool) for v in value):
        return [float(v) for v in value]
    return value


def run(args: argparse.Namespace) -> int:
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
        current = calls.call("get", names=[args.name]).values[0]
        if args.verb == "get":
            if current.type == NOT_SET:
                print(f"stillframe param: {target} has no parameter {args.name!r}",
                      file=sys.stderr)
                return 1
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
    if args.json:
        emit_json(rows if args.verb == "list" else rows[0])
    elif args.verb == "get":
        print(rows[0]["value"])
    else:
        print(format_table(["name", "type", "value", "read-only"],
                           [[r["name"], r["type"], r["value"], "yes" if r["read_only"] else ""]
                            for r in rows]))
    return 0


#: the DDS vendor of each backend's participants (endpoint GUIDs carry the vendor's id)
BACKEND_VENDORS = {"rclpy": "Fast DDS", "dds": "Cyclone DDS"}


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


def run_load(args: argparse.Namespace) -> int:
    target = node_name(args.node)
    wanted = load_param_file(args.file, target)
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
