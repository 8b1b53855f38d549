"""``stillframe daemon start|stop|status``: the graph daemon the ``topic``/``node`` verbs ask, like
``ros2 daemon`` (:mod:`stillframe.app.graph_daemon`). The verbs start it on demand; it stops
after two hours without a question (``STILLFRAME_DAEMON_IDLE_S``) or when told to."""

from __future__ import annotations

import argparse
import sys

from stillframe.app.ros_tools import add_verbs


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe daemon``, its arguments and :func:`run` as its action to ``sub``."""
    verbs = add_verbs(sub, "daemon", "the graph cache the topic and node verbs ask (like ros2 "
                                     "daemon)")
    for verb, text in (("start", "start the daemon if it is not running"),
                       ("stop", "stop the daemon if it is running"),
                       ("status", "whether the daemon is running")):
        verbs.add_parser(verb, help=text).set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Start, stop or ask after the graph daemon and say what it did; exit code 1 when ``start``
    could not start it (its log named on stderr), else 0."""
    from stillframe.app import graph_daemon

    running = graph_daemon.is_running()
    if args.verb == "start":
        if running:
            print("The daemon is already running")
            return 0
        if not graph_daemon.start():
            log = graph_daemon.socket_path().with_suffix(".log")
            print(f"stillframe daemon: the daemon did not start (its log: {log})",
                  file=sys.stderr)
            return 1
        print("The daemon has been started")
    elif args.verb == "stop":
        print("The daemon has been stopped" if running and graph_daemon.stop()
              else "The daemon is not running")
    else:
        print("The daemon is running" if running else "The daemon is not running")
    return 0
