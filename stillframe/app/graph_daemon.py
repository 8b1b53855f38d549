"""The graph daemon: a process that keeps one node in the ROS graph and answers the command-line
tools' graph queries from it, as ros2's daemon does (``ros2 daemon``), so a warm ``stillframe
topic list`` needs neither DDS nor discovery.

One daemon per user, installation and graph setting (``ROS_DOMAIN_ID``, the discovery variables,
the backend): it listens on a Unix socket named by them (:func:`socket_path`), so tools in other
shells with other settings get their own. A tool asking for the graph starts the daemon when none
answers (:func:`graph`, ``start=True``), waits until it has settled discovery and asks it; the
daemon stops after :data:`IDLE_ENV` seconds without a question (two hours by default, as ros2's)
or on ``stillframe daemon stop``. Requests are one JSON line each way: ``{"op": "graph"}`` (the
snapshot of :class:`stillframe.middleware.graph.Graph`), ``{"op": "status"}``, ``{"op": "stop"}``.

The client side imports nothing heavy (no DDS, rclpy, numpy or message types).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import select
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from stillframe.config.environment import value
from stillframe.locations import PACKAGE_DIR
from stillframe.middleware.backend_choice import backend_name
from stillframe.middleware.graph import Graph

#: seconds without a request after which the daemon exits (default two hours, as ros2 daemon)
IDLE_ENV = "STILLFRAME_DAEMON_IDLE_S"
#: how long a tool waits for a daemon it started to answer [s]
START_TIMEOUT_S = 30.0
#: the environment that decides which graph a node sees
GRAPH_ENV = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS",
             "ROS_LOCALHOST_ONLY", "CYCLONEDDS_URI")
#: the daemon node's name: hidden (a leading '_'), as ros2's ``_ros2cli_daemon_...``
NODE_PREFIX = "_stillframe_daemon"


def socket_path() -> Path:
    """The daemon's socket for this user, environment and backend, and this installation (the
    interpreter and the package: two checkouts never talk to each other's daemon)."""
    setting = {name: value(name) for name in GRAPH_ENV}
    setting["backend"] = backend_name()
    setting["installation"] = f"{sys.executable} {PACKAGE_DIR}"
    digest = hashlib.sha1(json.dumps(setting, sort_keys=True).encode()).hexdigest()[:12]
    domain = setting["ROS_DOMAIN_ID"]
    return (Path(tempfile.gettempdir()) / f"stillframe-daemon-{os.getuid()}"
            / f"d{domain}-{setting['backend']}-{digest}.sock")


def request(op: str, path: Path | None = None, timeout_s: float = 10.0) -> dict[str, Any] | None:
    """The daemon's answer to ``op``, or None when no daemon listens at ``path``."""
    path = path or socket_path()
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout_s)
        try:
            sock.connect(str(path))
            sock.sendall(json.dumps({"op": op}).encode() + b"\n")
            data = b""
            while not data.endswith(b"\n"):
                chunk = sock.recv(1 << 16)
                if not chunk:
                    return None
                data += chunk
        except OSError:
            return None
    return json.loads(data)


def is_running() -> bool:
    """Whether a graph daemon answers at :func:`socket_path` now (this user, environment, backend
    and installation)."""
    return request("status") is not None


def start(*, wait: bool = True) -> bool:
    """Start the daemon unless one answers; with ``wait``, until it answers (False if it did
    not within :data:`START_TIMEOUT_S`). A lock file keeps two tools from starting two."""
    path = socket_path()
    path.parent.mkdir(mode=0o700, exist_ok=True)
    with open(path.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if is_running():
            return True
        log = open(path.with_suffix(".log"), "w")  # noqa: SIM115 (the daemon's stderr)
        daemon = subprocess.Popen(
            [sys.executable, "-m", "stillframe.app.graph_daemon", str(path)],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log,
            start_new_session=True, close_fds=True)
        log.close()
        if not wait:
            return True
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline and daemon.poll() is None:  # it may fail at once
            if is_running():
                return True
            time.sleep(0.05)
    return False


def stop() -> bool:
    """Stop the daemon; False if none was running."""
    return request("stop") is not None


def graph(*, start_daemon: bool = True) -> Graph | None:
    """The daemon's graph (starting the daemon first if asked); None if there is none."""
    answer = request("graph")
    if answer is None and start_daemon and start():
        answer = request("graph")
    return None if answer is None else Graph.from_json(answer)


def serve(path: Path, idle_s: float) -> None:
    """The daemon: a hidden node, discovery settled, then graph questions answered on ``path``
    until ``stop``, SIGTERM or ``idle_s`` seconds without one."""
    from stillframe.middleware import api
    from stillframe.middleware.graph import ANNOUNCE_S, settle, snapshot

    node = api.create_node(f"{NODE_PREFIX}_{os.getpid()}",
                           argv=["stillframe", "--ros-args", "--log-level", "warn"])
    settle_s, settled = settle(node)
    ready = time.monotonic()
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    server.listen(16)
    started, last = time.time(), time.monotonic()
    try:
        while api.ok() and time.monotonic() - last < idle_s:
            node.spin_once(0.02)
            if not select.select([server], [], [], 0)[0]:
                continue
            conn, _ = server.accept()
            last = time.monotonic()
            with conn:
                conn.settimeout(2.0)
                try:
                    op = json.loads(conn.makefile("rb").readline() or b"{}").get("op")
                except (OSError, ValueError):
                    continue
                if op == "graph":
                    answer = snapshot(node)
                    # a graph still changing at start-up has had time to settle since
                    answer.settle_s = settle_s
                    answer.settled = settled or time.monotonic() - ready >= ANNOUNCE_S
                    reply: dict[str, Any] = answer.to_json()
                else:
                    reply = {"pid": os.getpid(), "backend": node.backend, "started": started,
                             "domain": value("ROS_DOMAIN_ID")}
                with contextlib.suppress(OSError):
                    conn.sendall(json.dumps(reply).encode() + b"\n")
                if op == "stop":
                    break
    finally:
        server.close()
        for leftover in (path, path.with_suffix(".log")):  # the log is kept only if it failed
            with contextlib.suppress(FileNotFoundError):
                leftover.unlink()
        node.destroy_node()


if __name__ == "__main__":
    serve(Path(sys.argv[1]), float(value(IDLE_ENV)))
