"""``stillframe param list|get|set NODE [NAME [VALUE]]``: a running node's parameters through
the standard parameter services (``rcl_interfaces/srv/ListParameters``, ``GetParameters``,
``SetParameters``, ``DescribeParameters`` under ``NODE/``), like ``ros2 param``.

On the ``rclpy`` backend the calls go through rclpy's service clients, on ``dds`` through
:mod:`stillframe.middleware.dds_services`. NODE is a fully qualified name (``/frame/sim_node``)
or a bare name in the loop's namespace (``controller_node`` is ``/frame/controller_node``).
VALUE is parsed as YAML like ``-p NAME:=VALUE``; an integer for a double parameter is sent as a
double. A refused set prints the node's reason and exits 1.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from stillframe.app.commands.common import add_json_argument, emit_json
from stillframe.contract import messages, topics
from stillframe.errors import InputError
from stillframe.middleware import api, names
from stillframe.middleware.param_messages import (
    DOUBLE,
    DOUBLE_ARRAY,
    NOT_SET,
    TYPE_NAMES,
    value_msg,
    value_of,
)
from stillframe.middleware.params import parse_value
from stillframe.text_table import format_table

SERVICE_TYPES = {"list": "ListParameters", "get": "GetParameters", "set": "SetParameters",
                 "describe": "DescribeParameters"}


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("param", help="list, get and set a running node's parameters "
                            "(like ros2 param)")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    for verb, text in (("list", "every parameter with its type, value and read-only flag"),
                       ("get", "one parameter's value"), ("set", "set one parameter")):
        command = verbs.add_parser(verb, help=text)
        command.add_argument("node", metavar="NODE", help="e.g. /frame/controller_node")
        if verb != "list":
            command.add_argument("name", metavar="NAME")
        if verb == "set":
            command.add_argument("value", metavar="VALUE", help="YAML, e.g. 0.5, false, [1, 2]")
        command.add_argument("--timeout", type=float, default=10.0, metavar="S",
                             help="wait at most S seconds for the node (default 10)")
        add_json_argument(command)
        command.set_defaults(func=run)


def node_name(text: str) -> str:
    """The fully qualified node name of NODE (bare names are in the loop's namespace)."""
    full = text if text.startswith("/") else f"{topics.DEFAULT_NAMESPACE}/{text}"
    namespace, _, name = full.rpartition("/")
    names.validate_node_name(name)
    names.validate_namespace(namespace or "/")
    return full


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
                f"(is it running, on ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}?)")
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
    target = node_name(args.node)
    if args.verb == "set":
        value = parse_value(args.value, f"VALUE of {args.name}")
    node = api.create_node(f"_stillframe_param_{os.getpid()}", argv=["stillframe"])
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
