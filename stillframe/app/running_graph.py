"""Two launches on one ROS domain: the second refuses at start, naming the first.

The loop's nodes have fixed names in ``/frame`` and share ``/clock`` and ``/diagnostics``, so two
loops on one domain would each take the other's samples and commands (refused by their writer
gates, both then stall). Like a second ``ros2 launch`` of the same nodes, but with one line
instead of a silent stall: before it starts any child, a launch looks at the graph for
:data:`LOOK_S`; if it sees the loop's nodes, or another launcher that started earlier, it stops
with an :class:`~stillframe.errors.InputError` (exit code 2) naming them and the domain. Two
launches started in the same second see each other's launcher nodes, whose names carry their
start time: the later one refuses, the earlier one runs. Discovery under a heavy load can take
longer than :data:`LOOK_S`; a running launch therefore keeps looking for an earlier launcher
(every :data:`WATCH_S`) and, finding one, stops its nodes and refuses the same way.
"""

from __future__ import annotations

import os
import time

from stillframe.config.environment import value
from stillframe.contract import topics
from stillframe.errors import InputError
from stillframe.middleware import api

#: how long [s] a launch looks at the graph before starting its children (discovery on one host
#: takes well under a second)
LOOK_S = 1.0
#: how often [s] a running launch looks again for an earlier one that discovery showed late
WATCH_S = 1.0
#: the prefix of a launcher's hidden node, followed by its pid and its start time (ns)
LAUNCHER_PREFIX = "_stillframe_launch_"


def launcher_name(started_ns: int | None = None) -> str:
    """This process's launcher node name: the prefix, the pid and the start time."""
    return f"{LAUNCHER_PREFIX}{os.getpid()}_{started_ns or time.time_ns()}"


def _pid_started(name: str) -> tuple[int, int]:
    """The pid and start time in a launcher's node name ((0, 0) if it has none)."""
    try:
        pid, started = name.removeprefix(LAUNCHER_PREFIX).split("_")
        return int(pid), int(started)
    except ValueError:
        return 0, 0


def others(node: api.Node, loop_nodes: tuple[str, ...]) -> list[str]:
    """The running loop's nodes (``loop_nodes`` in ``/frame``) and the launchers of other
    processes started before this one, as the graph shows them now (``/namespace/name``; an
    earlier launch of this process, as in ``reproduce``, is over)."""
    mine = _pid_started(node.get_name())
    return sorted(
        f"{namespace.rstrip('/')}/{name}"
        for name, namespace in node.get_node_names_and_namespaces()
        if (name in loop_nodes and namespace.rstrip("/") == topics.DEFAULT_NAMESPACE)
        or (name.startswith(LAUNCHER_PREFIX) and _pid_started(name)[0] != mine[0]
            and _pid_started(name)[::-1] < mine[::-1]))


def refuse_if_running(node: api.Node, since: float, loop_nodes: tuple[str, ...]) -> None:
    """Look at the graph until :data:`LOOK_S` after ``since`` (monotonic s, when ``node`` was
    created); InputError naming the running graph if another loop (``loop_nodes``) or an earlier
    launch is there."""
    api.spin_until(node, lambda: bool(others(node, loop_nodes)),
                   max(0.0, since + LOOK_S - time.monotonic()))
    check(node, loop_nodes)


def check(node: api.Node, loop_nodes: tuple[str, ...] = ()) -> None:
    """InputError naming the running graph if the graph shows it now; with no ``loop_nodes``
    (a launch whose own nodes run), only an earlier launch: discovered late, under load, by
    the launch's watch during its run (:data:`WATCH_S`)."""
    if found := others(node, loop_nodes):
        domain = value("ROS_DOMAIN_ID")
        raise InputError(f"another stillframe loop is running on ROS_DOMAIN_ID={domain}: "
                         f"{', '.join(found)}; stop it or launch on another ROS_DOMAIN_ID")
