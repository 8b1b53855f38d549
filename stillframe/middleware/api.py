"""The backend-neutral node API, named like rclpy's.

```python
from stillframe.middleware.api import create_node, spin

node = create_node("sim_node", namespace="/frame")          # reads --ros-args from sys.argv
pub = node.create_publisher("sensor_msgs/msg/Imu", "floor1/imu", "sensor_data")
node.create_subscription("geometry_msgs/msg/WrenchStamped", "pendulum/torque_cmd", on_cmd, 10)
node.create_timer(0.01, step)
spin(node)            # returns on SIGINT / SIGTERM
node.destroy_node()
```

Messages are ``rosbags`` message instances (see :mod:`stillframe.messages`); ``publish`` also
takes CDR bytes, and ``create_subscription(..., raw=True)`` hands the callback
``(cdr_bytes, MessageInfo)``. The backend is ``rclpy`` when ``import rclpy`` works and ``dds``
otherwise; the environment variable ``STILLFRAME_RMW=dds|rclpy`` overrides the choice.
"""

from __future__ import annotations

import functools
import gc
import importlib.util
import os
import signal
import sys
import threading
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from stillframe import messages
from stillframe.errors import InputError
from stillframe.middleware.clock import Clock, Time
from stillframe.middleware.logger import Logger
from stillframe.middleware.params import Parameter, SetCallback
from stillframe.middleware.params import SetParametersResult as SetParametersResult
from stillframe.middleware.qos import QoSProfile

BACKEND_ENV = "STILLFRAME_RMW"
BACKENDS = ("dds", "rclpy")


@dataclass(frozen=True)
class MessageInfo:
    """What a raw subscription learns about a sample besides its bytes (ns since the epoch;
    ``received_timestamp`` on the node's clock, i.e. sim time with ``use_sim_time``).
    ``publisher_gid``: the writer's GID (its DDS GUID, as ``endpoint_gid`` in the graph), empty
    where the backend does not expose it (rclpy Jazzy's message info carries none)."""

    source_timestamp: int
    received_timestamp: int
    publisher_gid: bytes = b""


@dataclass(frozen=True)
class TopicEndpointInfo:
    """One publisher or subscription of a topic, as discovered (like rclpy's)."""

    topic_name: str
    topic_type: str
    topic_type_hash: str
    endpoint_gid: bytes
    qos_profile: QoSProfile
    node_name: str = ""
    node_namespace: str = ""


class Publisher(Protocol):
    topic_name: str

    def publish(self, msg: Any) -> None: ...
    def get_subscription_count(self) -> int: ...
    def wait_for_all_acked(self, timeout_sec: float) -> bool: ...


class Subscription(Protocol):
    topic_name: str


class Timer(Protocol):
    def cancel(self) -> None: ...
    def reset(self) -> None: ...


class Node(Protocol):
    """What every backend's node offers."""

    backend: str

    def get_name(self) -> str: ...
    def get_namespace(self) -> str: ...
    def get_logger(self) -> Logger: ...
    def get_clock(self) -> Clock: ...
    def create_publisher(
        self, msg_type: str | type, topic: str, qos: QoSProfile | str | int
    ) -> Publisher: ...
    def create_subscription(
        self, msg_type: str | type, topic: str, callback: Callable[..., None],
        qos: QoSProfile | str | int, raw: bool = False,
    ) -> Subscription: ...
    def create_timer(
        self, period_s: float, callback: Callable[[], None], clock: Clock | None = None
    ) -> Timer: ...
    def declare_parameter(
        self, name: str, default: Any = None, read_only: bool = False
    ) -> Parameter: ...
    def get_parameter(self, name: str) -> Parameter: ...
    def add_on_set_parameters_callback(self, callback: SetCallback) -> None: ...
    def call_service(
        self, srv_type: str, service: str, request: Any, timeout_sec: float
    ) -> Any | None: ...
    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]: ...
    def get_publishers_info_by_topic(self, topic: str) -> list[TopicEndpointInfo]: ...
    def get_subscriptions_info_by_topic(self, topic: str) -> list[TopicEndpointInfo]: ...
    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]: ...
    def spin_once(self, timeout_sec: float | None = None) -> None: ...
    def destroy_node(self) -> None: ...


#: samples per topic that did not decode (malformed CDR), dropped by the subscriptions of this
#: process; the loop nodes report them in ``/diagnostics``
MALFORMED: Counter[str] = Counter()


def deliver(callback: Callable[[Any], None], data: bytes | memoryview, type_name: str,
            topic: str) -> None:
    """Decode ``data`` and hand it to ``callback``; a malformed sample is dropped and counted."""
    msg = messages.decode_sample(data, type_name)
    if msg is None:
        MALFORMED[topic] += 1
    else:
        callback(msg)


_shutdown = threading.Event()
_handlers_installed = False
_gc_frozen = False


def ok() -> bool:
    """False once SIGINT/SIGTERM arrived or :func:`shutdown` was called."""
    return not _shutdown.is_set()


def shutdown() -> None:
    """Ask every :func:`spin` of this process to return."""
    _shutdown.set()


def _on_signal(signum: int, frame: Any) -> None:
    if _shutdown.is_set():  # second Ctrl-C: the user insists
        signal.default_int_handler(signum, frame)
    _shutdown.set()


def install_signal_handlers() -> None:
    """Make SIGINT and SIGTERM request a clean shutdown (main thread only; idempotent)."""
    global _handlers_installed
    if _handlers_installed or threading.current_thread() is not threading.main_thread():
        return
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    _handlers_installed = True


def has_rclpy() -> bool:
    """Whether real rclpy is importable (installed from PyPI by ``stillframe[ros]``)."""
    return importlib.util.find_spec("rclpy") is not None


def check_backend(backend: str, what: str) -> str:
    """``backend`` if it is one of :data:`BACKENDS` and usable here; InputError naming ``what``."""
    if backend not in BACKENDS:
        raise InputError(f"{what}: unknown backend {backend!r} (expected one of "
                         f"{', '.join(BACKENDS)})")
    if backend == "rclpy" and not has_rclpy():
        raise InputError(f"{what}: rclpy cannot be imported here (pip install 'stillframe[ros]', "
                         "or source a ROS 2 Jazzy install)")
    return backend


def backend_name() -> str:
    """``STILLFRAME_RMW`` if set, else ``rclpy`` when importable, else ``dds``."""
    chosen = os.environ.get(BACKEND_ENV, "").strip()
    if not chosen:
        return "rclpy" if has_rclpy() else "dds"
    return check_backend(chosen, f"{BACKEND_ENV}={chosen}")


def create_node(name: str, namespace: str | None = None, argv: list[str] | None = None,
                backend: str | None = None) -> Node:
    """A node on ``backend`` (default :func:`backend_name`); ``argv`` (default ``sys.argv``)
    may carry ``--ros-args``.

    ``namespace`` is the default namespace (``-r __ns:=`` overrides it, as does ``__node``
    the name). Logs the backend in use.
    """
    backend = check_backend(backend, "backend") if backend else backend_name()
    args = list(sys.argv if argv is None else argv)[1:]
    if backend == "dds":
        from stillframe.middleware.dds_services import ServiceNode as NodeClass
    else:
        from stillframe.middleware.rclpy_backend import RclpyNode as NodeClass
    node = NodeClass(name, namespace or "/", args)
    install_signal_handlers()
    node.get_logger().info(f"middleware backend: {backend}", once=True)
    return node


def freeze_setup_objects() -> None:
    """Move every object alive now to the collector's permanent generation (once per process).

    Called when a node starts spinning: the objects made while setting up (type store,
    modules, models) live as long as the process, and a full collection pass over them takes
    10-40 ms, a latency spike in the middle of a control loop. Objects made later are
    collected as usual."""
    global _gc_frozen
    if not _gc_frozen:
        gc.freeze()
        _gc_frozen = True


def node_main(main: Callable[[], int | None]) -> Callable[[], int]:
    """Wrap a node executable's ``main`` (a ``console_scripts`` entry point): bad input
    (:class:`InputError`, e.g. a wrong parameter) prints one line and exits with code 2."""

    @functools.wraps(main)
    def wrapped() -> int:
        try:
            return int(main() or 0)
        except InputError as exc:
            print(f"{Path(sys.argv[0]).name}: error: {exc}", file=sys.stderr)
            return 2

    return wrapped


def spin_once(node: Node, timeout_sec: float | None = None) -> None:
    """Wait up to ``timeout_sec`` (None: until something happens) and run ready callbacks."""
    node.spin_once(timeout_sec)


def spin(node: Node) -> None:
    """Run the node's callbacks until SIGINT, SIGTERM or :func:`shutdown`."""
    while ok():
        node.spin_once(None)


def spin_until(node: Node, condition: Callable[[], bool], timeout_sec: float) -> bool:
    """Spin until ``condition()`` is true (returns True), the timeout passes or shutdown."""
    deadline = Time(Clock().now().nanoseconds + int(timeout_sec * 1e9))
    while ok() and not condition():
        remaining = (deadline.nanoseconds - Clock().now().nanoseconds) * 1e-9
        if remaining <= 0:
            return False
        node.spin_once(min(remaining, 0.05))
    return condition()
