"""``stillframe lifecycle get|list|set NODE [TRANSITION]``: a managed node's state and its
transitions through the standard ``lifecycle_msgs`` services (``NODE/get_state``,
``NODE/get_available_transitions``, ``NODE/change_state``), like ``ros2 lifecycle``.

On the ``rclpy`` backend the calls go through rclpy's service clients, on ``dds`` through
:mod:`stillframe.middleware.dds_services` (``STILLFRAME_RMW`` chooses, as for ``stillframe
param``). NODE as for ``stillframe param`` (``controller_node`` is ``/frame/controller_node``).
An unknown node, an unknown transition or a node that is not managed is one line, exit 2; a
transition the node refuses in its current state prints the node's reason, exit 1.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any

from stillframe.app.arguments import add_json_argument, emit_json
from stillframe.app.ros_tools import node_name
from stillframe.config.environment import value
from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.middleware import api, lifecycle


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe lifecycle``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("lifecycle", help="a managed node's state and transitions "
                            "(like ros2 lifecycle)")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    for verb, text in (("get", "the node's current state"),
                       ("list", "the transitions available in the current state"),
                       ("set", "trigger a transition")):
        command = verbs.add_parser(verb, help=text)
        command.add_argument("node", metavar="NODE", help="e.g. /frame/controller_node")
        if verb == "set":
            command.add_argument("transition", metavar="TRANSITION",
                                 help=", ".join(lifecycle.PUBLIC))
        command.add_argument("--timeout", type=float, default=10.0, metavar="S",
                             help="wait at most S seconds for the node (default 10)")
        add_json_argument(command)
        command.set_defaults(func=run)


class LifecycleCalls:
    """The lifecycle services of one remote node, called from a hidden local node."""

    def __init__(self, node: api.Node, target: str, timeout_sec: float) -> None:
        self.node = node
        self.target = target
        self.deadline = time.monotonic() + timeout_sec

    def find_node(self) -> None:
        """Wait until the target is in the graph; InputError naming it when it does not come."""
        namespace, _, name = self.target.rpartition("/")
        while (name, namespace or "/") not in self.node.get_node_names_and_namespaces():
            if time.monotonic() >= self.deadline:
                raise InputError(
                    f"unknown node {self.target}: not in the graph on ROS_DOMAIN_ID="
                    f"{value('ROS_DOMAIN_ID')}")
            self.node.spin_once(0.1)

    def call(self, service: str, **fields: Any) -> Any:
        """Call the target's lifecycle ``service`` (a key of
        :data:`stillframe.middleware.lifecycle.SERVICES`) with the request ``fields`` and return
        the response; an :class:`~stillframe.errors.InputError` when it does not answer (the
        target is not a managed node)."""
        srv = lifecycle.SERVICES[service]
        request = messages.new(f"lifecycle_msgs/srv/{srv}_Request", **fields)
        # a node in the graph serves its lifecycle services at once; 2 s at least for a slow one
        wait = max(self.deadline - time.monotonic(), 2.0)
        response = self.node.call_service(f"lifecycle_msgs/srv/{srv}",
                                          f"{self.target}/{service}", request, wait)
        if response is None:
            raise InputError(f"node {self.target} is not a managed node (no answer on "
                             f"{self.target}/{service} within {wait:.3g} s)")
        return response

    def state(self) -> str:
        """The label of the target's current state (``get_state``)."""
        return str(self.call("get_state").current_state.label)

    def available(self) -> list[str]:
        """The labels of the transitions available from the target's current state."""
        return [t.transition.label
                for t in self.call("get_available_transitions").available_transitions]


def run(args: argparse.Namespace) -> int:
    """Ask or change the managed node's state through its lifecycle services; exit code 1 when the
    node refused the transition (the reason on stderr), else 0."""
    target = node_name(args.node)
    if args.verb == "set" and args.transition not in lifecycle.PUBLIC:
        raise InputError(f"unknown transition {args.transition!r} (expected one of "
                         f"{', '.join(lifecycle.PUBLIC)})")
    node = api.create_node(f"_stillframe_lifecycle_{os.getpid()}", argv=["stillframe"])
    try:
        calls = LifecycleCalls(node, target, args.timeout)
        calls.find_node()
        if args.verb == "get":
            state = calls.state()
            return show(args, {"node": target, "state": state}, state)
        if args.verb == "list":
            available = calls.available()
            return show(args, {"node": target, "state": calls.state(), "available": available},
                        "\n".join(available))
        transition = messages.new("lifecycle_msgs/msg/Transition", label=args.transition)
        before = calls.state()
        success = bool(calls.call("change_state", transition=transition).success)
        after, available = calls.state(), calls.available()
    finally:
        node.destroy_node()
    reason = "" if success else (
        f"no transition {args.transition} from state {before} (available: "
        f"{', '.join(available) or 'none'})" if before == after and args.transition not in
        available else f"the node's {args.transition} failed (now {after}; see its log)")
    if args.json:
        emit_json({"node": target, "transition": args.transition, "successful": success,
                   "state": after, "reason": reason})
    elif success:
        print(f"{target}: {args.transition}: {before} -> {after}")
    if not success:
        print(f"stillframe lifecycle: {target} refused {args.transition}: {reason}",
              file=sys.stderr)
        return 1
    return 0


def show(args: argparse.Namespace, document: dict[str, Any], text: str) -> int:
    """Print ``document`` as JSON with ``--json``, else ``text``; exit code 0."""
    if args.json:
        emit_json(document)
    else:
        print(text)
    return 0
