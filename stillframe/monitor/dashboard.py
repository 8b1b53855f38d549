"""The built-in live dashboard: decimated plot data from the loop's topics, served over HTTP.

One page (``stillframe/data/dashboard.html``) of Plotly charts: per floor the true and
estimated displacement (``state_truth``, ``state_estimate``) with the measured acceleration
(``floorN/imu``); the pendulum angle; the command (torque in N·m on the left axis, force in N on
the right) with its limits; on the pH plant its energy balance (``energy_balance``: H and the port
and dissipated powers); the controller's start marked on every chart; and each node's counters
from ``/diagnostics``, red when an error counter is non-zero; with the modal tracker running
(``launch --track``), the current tracked modes of ``identification/modes`` (frequency and damping
ratio, each with its 95 % interval). The page polls ``/data`` twice a second. Decimation happens
before any work is done on a sample: the loop's topics are read from their monitor taps
(:mod:`stillframe.middleware.taps`, thinned by the loop's writers) when published, else from the
topics, by polled subscriptions (KEEP_LAST 1), and every ``1 / rate_hz`` s of wall time the
newest sample of each is taken, decoded and kept; each series keeps its last ``points`` samples.
So a 1 kHz topic costs neither the loop nor this process a send or a wake-up per sample, and the
page always gets at most ``points`` points per series.

Plotly's JavaScript is served from the ``plotly`` Python package (``plotly.min.js``), so the
page needs no internet.
"""

from __future__ import annotations

import json
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any

from plotly.offline import get_plotlyjs

from stillframe.contract import messages
from stillframe.contract.topics import (
    DIAGNOSTICS,
    ENERGY_BALANCE,
    FLOOR_IMU,
    FORCE_CMD,
    PENDULUM_JOINT_STATES,
    STATE_ESTIMATE,
    STATE_TRUTH,
    STATUS_KEYS,
    TORQUE_CMD,
    TopicSpec,
)
from stillframe.identification.tracker import MODES_TOPIC, mode_records
from stillframe.middleware.qos import QoSProfile, Reliability
from stillframe.middleware.taps import TAP_RATE_HZ
from stillframe.middleware.topic_follower import RawCallback, TopicFollower

__all__ = ["CHARTS", "ERROR_KEYS", "SERIES", "Dashboard", "Limits", "Series", "serve"]

#: counters that are errors when non-zero (the rest of STATUS_KEYS are progress figures)
ERROR_KEYS: tuple[str, ...] = tuple(k for k in STATUS_KEYS
                                    if k not in ("sim_time_s", "step", "realtime_factor"))
#: best effort, the newest sample only: the dashboard never back-pressures a publisher
WATCH_QOS = QoSProfile(depth=1, reliability=Reliability.BEST_EFFORT)
#: best effort with a short queue for ``/diagnostics`` (every node's status counts)
DIAGNOSTICS_QOS = QoSProfile(depth=10, reliability=Reliability.BEST_EFFORT)


def _joint_positions(msg: Any) -> list[float]:
    return [float(v) for v in msg.position[:4]]


#: series name -> (topic, values of a message); the page knows these names
SERIES: dict[str, tuple[TopicSpec, Callable[[Any], list[float]]]] = {
    "truth": (STATE_TRUTH, _joint_positions),
    "estimate": (STATE_ESTIMATE, _joint_positions),
    **{f"imu{n + 1}": (spec, lambda m: [float(m.linear_acceleration.x)])
       for n, spec in enumerate(FLOOR_IMU)},
    "encoder": (PENDULUM_JOINT_STATES, lambda m: [float(m.position[0])]),
    "torque_cmd": (TORQUE_CMD, lambda m: [float(m.wrench.torque.z)]),
    "force_cmd": (FORCE_CMD, lambda m: [float(m.wrench.force.x)]),
    "energy": (ENERGY_BALANCE, lambda m: [float(v) for v in m.data[1:]]),
}
#: a series' sample time where its message has no header (default: ``header.stamp``)
STAMPS: dict[str, Callable[[Any], float]] = {"energy": lambda m: float(m.data[0])}


def _header_stamp(msg: Any) -> float:
    return messages.stamp_ns(msg.header.stamp) * 1e-9


#: each chart of the page: (title, left axis, right axis or None), every axis with its unit
CHARTS: dict[str, tuple[str, str, str | None]] = {
    **{f"floor{n}": (f"floor {n}", "x [m]", "a [m/s²]") for n in (1, 2, 3)},
    "pendulum": ("pendulum angle", "φ [rad]", None),
    "command": ("command and limits", "torque [N·m]", "force [N]"),
    "energy": ("energy balance", "H [J]", "power [W]"),
}
TIME_AXIS = "t [s]"


class Series:
    """The last ``points`` samples kept, ``(stamp [s], values)``."""

    def __init__(self, points: int) -> None:
        self.samples: deque[tuple[float, list[float]]] = deque(maxlen=points)
        self.kept = 0

    def keep(self, sample: tuple[float, list[float]]) -> None:
        """Append ``(stamp [s], values)``, the oldest dropped past ``points``, and count it."""
        self.samples.append(sample)
        self.kept += 1

    def as_columns(self) -> dict[str, Any]:
        """``{"t": [...], "y": [[first value ...], [second value ...], ...]}``."""
        samples = list(self.samples)
        width = len(samples[0][1]) if samples else 0
        return {"t": [t for t, _ in samples],
                "y": [[v[i] for _, v in samples] for i in range(width)],
                "kept": self.kept}


@dataclass
class Limits:
    """The command limits drawn on the command plot (None: not set in the scene), and when the
    controller starts (``controller.start`` [s], marked on every chart; None: not known)."""

    command: float | None = None
    torque: float | None = None
    force: float | None = None
    controller_start: float | None = None


class Dashboard(TopicFollower):
    """Follows the loop's topics under ``namespace`` (their taps where published) and keeps
    decimated series and the latest ``/diagnostics`` values; :meth:`snapshot` is what ``/data``
    serves."""

    def __init__(self, node: Any, namespace: str, limits: Limits, rate_hz: float = 50.0,
                 points: int = 500) -> None:
        self.limits = limits
        self._lock = threading.Lock()
        self.series = {name: Series(points) for name in SERIES}
        #: topic -> (series name, the values of a message)
        self._by_topic = {f"{namespace}/{spec.name}": (name, values)
                          for name, (spec, values) in SERIES.items()}
        self.diagnostics: dict[str, dict[str, str]] = {}
        #: the tracker's latest modes (:func:`~stillframe.identification.tracker.mode_records`)
        self.tracked_modes: list[dict[str, Any]] = []
        self.tracked_updates = 0
        super().__init__(node, list(self._by_topic), poll_period_s=1.0 / rate_hz,
                         read_taps=rate_hz <= TAP_RATE_HZ, newest_only=True)
        node.create_subscription(DIAGNOSTICS.type_name, DIAGNOSTICS.name, self._on_diagnostics,
                                 DIAGNOSTICS_QOS)
        node.create_subscription("std_msgs/msg/Float64MultiArray", f"{namespace}/{MODES_TOPIC}",
                                 self._on_modes, WATCH_QOS)

    def request(self, offers: list[QoSProfile]) -> QoSProfile:
        """:data:`WATCH_QOS` whatever the publishers offer: best effort, the newest sample only."""
        return WATCH_QOS

    def on_new_topic(self, topic: str, msgtype: str, offers: list[QoSProfile]) -> RawCallback:
        """The callback that decodes each sample of ``topic`` and keeps its stamp and values in the
        topic's :class:`Series`."""
        name, values = self._by_topic[topic]
        stamp = STAMPS.get(name, _header_stamp)

        def keep(data: bytes, _: Any) -> None:
            """Keep the newest sample of the topic (one per poll: the reader keeps one)."""
            msg = messages.deserialize(data, msgtype)
            with self._lock:
                self.series[name].keep((stamp(msg), values(msg)))

        return keep

    def _on_diagnostics(self, msg: Any) -> None:
        with self._lock:
            for status in msg.status:
                self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values
                                                 if kv.key in STATUS_KEYS}

    def _on_modes(self, msg: Any) -> None:
        modes = mode_records(msg.data)
        with self._lock:
            self.tracked_modes = modes
            self.tracked_updates += 1

    def snapshot(self) -> dict[str, Any]:
        """Everything the page draws, JSON-ready."""
        with self._lock:
            return {"series": {name: s.as_columns() for name, s in self.series.items()},
                    "diagnostics": {k: dict(v) for k, v in self.diagnostics.items()},
                    "error_keys": list(ERROR_KEYS),
                    "tracked_modes": {"modes": list(self.tracked_modes),
                                      "updates": self.tracked_updates},
                    "limits": {"command": self.limits.command, "torque": self.limits.torque,
                               "force": self.limits.force},
                    "controller_start": self.limits.controller_start,
                    "charts": CHARTS, "time_axis": TIME_AXIS}


def _asset(package: str, name: str) -> bytes:
    return resources.files(package).joinpath(name).read_bytes()


def serve(dashboard: Dashboard, host: str, port: int) -> ThreadingHTTPServer:
    """Serve the page, ``plotly.min.js`` and ``/data`` on ``host:port`` from a daemon thread
    (``server.server_address`` has the port when 0 was asked for)."""
    files = {"/": ("text/html; charset=utf-8", _asset("stillframe", "data/dashboard.html")),
             "/plotly.min.js": ("application/javascript", get_plotlyjs().encode())}

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            if self.path == "/data":
                kind, body = "application/json", json.dumps(dashboard.snapshot()).encode()
            elif self.path in files:
                kind, body = files[self.path]
            else:
                self.send_error(404)
                return
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, format: str, *args: Any) -> None:
            """Quiet: one line per poll would drown the launch's output."""

    server = ThreadingHTTPServer((host, port), Handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, name="dashboard", daemon=True).start()
    return server
