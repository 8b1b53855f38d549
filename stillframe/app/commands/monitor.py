"""``stillframe monitor [TOPIC ...]``: the ROS graph live in Foxglove/Lichtblick and a dashboard.

Bridges the topics (all of them by default) to the Foxglove WebSocket protocol (the WebSocket
subprotocol ``foxglove.sdk.v1``, ``ros2msg`` schemas, CDR messages) on ``ws://HOST:PORT``, for
Foxglove and Lichtblick; with ``--dashboard`` also serves the built-in live dashboard on
``http://HOST:DASHBOARD_PORT``. Runs until Ctrl-C. See docs/monitor.md.
"""

from __future__ import annotations

import argparse
import math
import sys

from stillframe.app.arguments import (
    add_priority_arguments,
    apply_priority,
    scene_path,
)
from stillframe.errors import InputError

READY_LINE = "Monitor ready"
#: samples forwarded per second and topic at most, by default: a live plot shows no more, and
#: the loop does not pay for the rest (docs/monitor.md)
MAX_RATE_HZ = 50.0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe monitor``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser(
        "monitor", help="bridge topics to Foxglove (WebSocket) and serve a live dashboard",
        description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("topics", nargs="*", metavar="TOPIC",
                        help="topics to bridge (default: every topic)")
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to bind (default 127.0.0.1: this machine only)")
    parser.add_argument("--port", type=int, default=8765,
                        help="Foxglove WebSocket port (default 8765; 0: any free port)")
    parser.add_argument("--max-rate", type=float, default=MAX_RATE_HZ, metavar="HZ",
                        help=f"forward at most HZ samples per second and topic (default "
                             f"{MAX_RATE_HZ:g}; 0: every sample, which costs a 1 kHz loop more; "
                             "docs/monitor.md)")
    parser.add_argument("--dashboard", action="store_true", help="also serve the dashboard")
    parser.add_argument("--dashboard-port", type=int, default=8080,
                        help="dashboard HTTP port (default 8080; 0: any free port)")
    parser.add_argument("--namespace", default="/frame",
                        help="the loop's namespace, for the dashboard (default /frame)")
    parser.add_argument("--scene", type=scene_path, default=None,
                        help="scene whose command limits the dashboard draws: a file, or the "
                             "name of a shipped scene (e.g. thesis_lqg), as for launch")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="with --scene: override a scene value")
    add_priority_arguments(parser, nice=10, who="monitor")
    parser.add_argument("--use-sim-time", action="store_true",
                        help="follow /clock: stamps and the Foxglove time cursor in sim time")
    parser.set_defaults(func=run)


def _check_port(name: str, port: int) -> None:
    if not 0 <= port <= 65535:
        raise InputError(f"{name} {port}: expected 0..65535")


def run(args: argparse.Namespace) -> int:
    """Serve the Foxglove bridge (and the dashboard with ``--dashboard``) until Ctrl-C; exit code 0.
    A port that cannot be served is an :class:`~stillframe.errors.InputError`."""
    from stillframe.config.scene import load_scene
    from stillframe.middleware.api import create_node, spin
    from stillframe.middleware.names import resolve_topic
    from stillframe.monitor.dashboard import Dashboard, Limits, serve
    from stillframe.monitor.foxglove_bridge import FoxgloveBridge

    _check_port("--port", args.port)
    _check_port("--dashboard-port", args.dashboard_port)
    if not (args.max_rate >= 0 and math.isfinite(args.max_rate)):
        raise InputError(f"--max-rate {args.max_rate:g}: expected a rate >= 0 Hz (0: every "
                         "sample)")
    limits = Limits()
    if args.scene is not None:
        scene = load_scene(args.scene, args.overrides)
        limits = Limits(scene.controller.limit, scene.actuators.torque_limit,
                        scene.actuators.force_limit, scene.controller.start)
    # after every input is checked (a refused command leaves its caller's priority alone), and
    # before the middleware's and the SDK's threads start (they inherit it)
    apply_priority(args)
    node = create_node("stillframe_monitor", argv=sys.argv[:1])
    try:
        try:
            bridge = FoxgloveBridge(node, args.host, args.port,
                                    [resolve_topic(t) for t in args.topics], args.max_rate,
                                    args.use_sim_time)
        except RuntimeError as exc:
            raise InputError(f"--port {args.port}: cannot serve on {args.host}: {exc}") from None
        server = bridge.server
        where = f"foxglove ws://{args.host}:{server.port}"
        if args.dashboard:
            try:
                http = serve(Dashboard(node, args.namespace, limits), args.host,
                             args.dashboard_port)
            except OSError as exc:
                raise InputError(f"--dashboard-port {args.dashboard_port}: {exc}") from None
            where += f", dashboard http://{args.host}:{http.server_address[1]}/"
        node.get_logger().info(f"{READY_LINE}: {where}")
        spin(node)
        server.stop()
        counts = ", ".join(f"{topic} {n}" for topic, n in sorted(bridge.forwarded.items()))
        node.get_logger().info(f"Forwarded {len(bridge.channels)} topics: {counts}")
    finally:
        node.destroy_node()
    return 0
