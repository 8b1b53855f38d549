"""What the node API's backends implement and share: the :class:`Node` protocol and its value
types, message delivery with the count of malformed samples, and the process's run state
(:func:`ok`, :func:`shutdown`, signal handlers, the frozen set-up objects).

The backends import this module; :mod:`stillframe.middleware.api` chooses a backend and re-exports
these names for node code.
"""

from __future__ import annotations

import gc
import signal
import threading
from collections import Counter
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

from stillframe.contract import messages
from stillframe.middleware.clock import Clock
from stillframe.middleware.graph import TopicEndpointInfo
from stillframe.middleware.logger import Logger
from stillframe.middleware.params import Parameter, ParameterDescriptor, SetCallback
from stillframe.middleware.qos import QoSProfile

__all__ = ["GIVE_UP_CHECK_S", "ManagedNode", "MessageInfo", "Node", "PolledSubscription",
           "Publisher", "Subscription", "Timer", "deliver", "freeze_setup_objects",
           "install_signal_handlers", "never_called", "node_created", "node_destroyed", "ok",
           "shutdown"]

#: how often a service call that may give up (``call_service(..., give_up=...)``) asks [s]
GIVE_UP_CHECK_S = 0.1

class MessageInfo(NamedTuple):
    """What a raw subscription learns about a sample besides its bytes (ns since the epoch;
    ``received_timestamp`` on the node's clock, i.e. sim time with ``use_sim_time``).
    ``publisher_gid``: the writer's GID (its DDS GUID, as ``endpoint_gid`` in the graph), empty
    where the backend does not expose it (rclpy Jazzy's message info carries none).
    ``publication_sequence``: the writer's sequence number of the sample (1, 2, … per writer; 0
    where the backend does not give it), what tells writers apart without GIDs
    (:mod:`stillframe.loop.writer_gate`). A tuple: one is made per sample on the loop's path (a
    frozen dataclass cost three times as much)."""

    source_timestamp: int
    received_timestamp: int
    publisher_gid: bytes = b""
    publication_sequence: int = 0


class Publisher(Protocol):
    topic_name: str

    def publish(self, msg: Any) -> None: ...
    def get_subscription_count(self) -> int: ...
    def wait_for_all_acked(self, timeout_sec: float) -> bool: ...


class Subscription(Protocol):
    topic_name: str

    def get_publisher_count(self) -> int: ...


def never_called(*_: Any) -> None:
    """The callback of a polled subscription (its samples are taken, never dispatched)."""


class PolledSubscription(Protocol):
    """A subscription that never calls back: its samples wait in the middleware (KEEP_LAST
    ``depth`` of them) until :meth:`take`. The process does no work per sample, only per
    take: what a viewer wants of a 1 kHz topic (Cyclone's advice for a time-based filter,
    which it does not implement at the writer: a keep-last reader, polled)."""

    topic_name: str

    def take(self) -> list[tuple[bytes, MessageInfo]]:
        """The samples waiting, oldest first (raw CDR with their info)."""
        ...


class Timer(Protocol):
    def cancel(self) -> None: ...
    def reset(self) -> None: ...


class Node(Protocol):
    """What every backend's node offers."""

    backend: str
    #: samples per topic that did not decode (malformed CDR), dropped by this node's
    #: subscriptions (:func:`deliver`, and the loop's raw readers); the loop nodes report them in
    #: ``/diagnostics``
    malformed: Counter[str]

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
    def create_polled_subscription(
        self, msg_type: str | type, topic: str, qos: QoSProfile | str | int,
    ) -> PolledSubscription: ...
    def destroy_subscription(self, sub: Subscription | PolledSubscription) -> None: ...
    def create_timer(
        self, period_s: float, callback: Callable[[], None], clock: Clock | None = None
    ) -> Timer: ...
    def declare_parameter(
        self, name: str, default: Any = None, read_only: bool = False, *,
        descriptor: ParameterDescriptor | None = None,
    ) -> Parameter: ...
    def get_parameter(self, name: str) -> Parameter: ...
    def add_on_set_parameters_callback(self, callback: SetCallback) -> None: ...
    def call_service(
        self, srv_type: str, service: str, request: Any, timeout_sec: float, *,
        give_up: Callable[[], bool] | None = None,
    ) -> Any | None: ...
    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]: ...
    def get_publishers_info_by_topic(self, topic: str) -> list[TopicEndpointInfo]: ...
    def count_publishers(self, topic: str) -> int: ...
    def get_subscriptions_info_by_topic(self, topic: str) -> list[TopicEndpointInfo]: ...
    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]: ...
    def get_service_names_and_types_by_node(
        self, node_name: str, node_namespace: str, server: bool = True
    ) -> list[tuple[str, list[str]]]: ...
    def spin_once(self, timeout_sec: float | None = None) -> None: ...
    def destroy_node(self) -> None: ...


class ManagedNode(Node, Protocol):
    """A lifecycle node (``api.create_node(..., managed=True)``): rcl_lifecycle's states and
    transitions (:mod:`.lifecycle`), served on the ``lifecycle_msgs`` services."""

    def manage(self, on_transition: Callable[[str], str]) -> None: ...
    def lifecycle_state(self) -> str: ...
    def trigger(self, transition: str) -> str: ...


def deliver(callback: Callable[[Any], None], data: bytes | memoryview, type_name: str,
            topic: str, malformed: Counter[str]) -> None:
    """Decode ``data`` and hand it to ``callback``; a malformed sample is dropped and counted in
    ``malformed`` (its node's :attr:`Node.malformed`)."""
    msg = messages.decode_sample(data, type_name)
    if msg is None:
        malformed[topic] += 1
    else:
        callback(msg)


_shutdown = threading.Event()
#: the handlers :func:`install_signal_handlers` replaced (empty: its own are not installed)
_replaced: dict[int, Any] = {}
#: the nodes of this process not destroyed yet (by id)
_live_nodes: set[int] = set()
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
    """Make SIGINT and SIGTERM request a clean shutdown (main thread only; idempotent) while
    this process has nodes (:func:`node_destroyed`)."""
    if _replaced or threading.current_thread() is not threading.main_thread():
        return
    for signum in (signal.SIGINT, signal.SIGTERM):
        _replaced[signum] = signal.signal(signum, _on_signal)


def node_created(node: object) -> None:
    """A node of this process exists (the node API counts them)."""
    _live_nodes.add(id(node))


def node_destroyed(node: object) -> None:
    """A node was destroyed. With the process's last node gone, the handlers from before
    :func:`install_signal_handlers` are back: no loop reads the shutdown request any more, so a
    signal from then on is the process's own again (:mod:`stillframe.interrupts`: one line and
    its exit code) rather than a request nobody sees."""
    _live_nodes.discard(id(node))
    if _live_nodes or not _replaced or threading.current_thread() is not threading.main_thread():
        return
    for signum, handler in _replaced.items():
        signal.signal(signum, handler)
    _replaced.clear()


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
