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
    (:mod:`stillframe.loop.writer_gate`). A tuple, the cheapest record to make: one is made per
    sample on the loop's path."""

    source_timestamp: int
    received_timestamp: int
    publisher_gid: bytes = b""
    publication_sequence: int = 0


class Publisher(Protocol):
    """A writer of one topic, as rclpy's ``Publisher``: ``topic_name`` is the fully qualified name
    after remapping."""

    topic_name: str

    def publish(self, msg: Any) -> None:
        """Send ``msg``: a ``rosbags`` message of the publisher's type, or its CDR bytes as they
        are."""

    def get_subscription_count(self) -> int:
        """How many readers are matched with this writer now (0 until discovery has matched
        them)."""

    def wait_for_all_acked(self, timeout_sec: float) -> bool:
        """Block until every reliable reader has acknowledged every sample written so far: True, or
        False once ``timeout_sec`` [s] passed first."""


class Subscription(Protocol):
    """A reader of one topic, as rclpy's ``Subscription``; its callback gets each message, or
    ``(cdr_bytes, MessageInfo)`` when it was created ``raw``."""

    topic_name: str

    def get_publisher_count(self) -> int:
        """How many writers are matched with this reader now."""


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
    """A periodic callback on a node's clock (with ``use_sim_time``, on ``/clock``), as rclpy's
    ``Timer``; it runs inside :func:`~stillframe.middleware.api.spin`."""

    def cancel(self) -> None:
        """Stop calling back until :meth:`reset`."""

    def reset(self) -> None:
        """Start the period again from now (and undo :meth:`cancel`)."""


class Node(Protocol):
    """What every backend's node offers."""

    backend: str
    #: samples per topic that did not decode (malformed CDR), dropped by this node's
    #: subscriptions (:func:`deliver`, and the loop's raw readers); the loop nodes report them in
    #: ``/diagnostics``
    malformed: Counter[str]

    def get_name(self) -> str:
        """The node's name after ``--ros-args -r __node:=`` remapping."""

    def get_namespace(self) -> str:
        """The node's namespace (``/`` at the root) after ``-r __ns:=`` remapping."""

    def get_logger(self) -> Logger:
        """The node's logger, named after the node as rclpy names it (``frame.sim_node``)."""

    def get_clock(self) -> Clock:
        """The node's clock: the system clock, or sim time from ``/clock`` with ``use_sim_time``."""

    def create_publisher(
        self, msg_type: str | type, topic: str, qos: QoSProfile | str | int
    ) -> Publisher:
        """A publisher of ``msg_type`` (a ``pkg/msg/Type`` name or a ``rosbags`` class) on ``topic``
        (relative names resolve in the node's namespace, then remapping applies); ``qos`` is a
        :class:`~stillframe.middleware.qos.QoSProfile`, a profile name such as ``"sensor_data"`` or
        a KEEP_LAST depth."""

    def create_subscription(
        self, msg_type: str | type, topic: str, callback: Callable[..., None],
        qos: QoSProfile | str | int, raw: bool = False,
    ) -> Subscription:
        """A subscription of ``msg_type`` on ``topic`` whose ``callback`` runs inside spin with each
        decoded message, or with ``(cdr_bytes, MessageInfo)`` when ``raw``. A sample that does not
        decode is dropped and counted in :attr:`malformed`."""

    def create_polled_subscription(
        self, msg_type: str | type, topic: str, qos: QoSProfile | str | int,
    ) -> PolledSubscription:
        """A :class:`PolledSubscription` of ``msg_type`` on ``topic``: its samples wait in the
        middleware until taken, and spin never runs anything for them."""

    def destroy_subscription(self, sub: Subscription | PolledSubscription) -> None:
        """Remove ``sub`` from the node and the graph; its callback is not called again."""

    def create_timer(
        self, period_s: float, callback: Callable[[], None], clock: Clock | None = None
    ) -> Timer:
        """A :class:`Timer` calling ``callback`` every ``period_s`` [s] (> 0) on ``clock``, by
        default the node's; a timer that fell behind skips the periods it missed, as rcl's does."""

    def declare_parameter(
        self, name: str, default: Any = None, read_only: bool = False, *,
        descriptor: ParameterDescriptor | None = None,
    ) -> Parameter:
        """Declare ``name`` with ``default`` (an ``--ros-args -p`` or params-file override wins) and
        return it; ``read_only`` refuses every later set. Declaring a name twice raises."""

    def get_parameter(self, name: str) -> Parameter:
        """The declared parameter ``name`` with its current value."""

    def add_on_set_parameters_callback(self, callback: SetCallback) -> None:
        """Ask ``callback`` before every set of this node's parameters; a result with ``successful``
        false refuses the whole set with its ``reason``."""

    def call_service(
        self, srv_type: str, service: str, request: Any, timeout_sec: float, *,
        give_up: Callable[[], bool] | None = None,
    ) -> Any | None:
        """Call ``service`` of type ``srv_type`` with ``request`` (a ``rosbags`` message) and return
        the response, or None when the service does not appear or answer within ``timeout_sec`` [s],
        or once ``give_up()`` holds while the reply is awaited."""

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every topic with a publisher or subscription in the graph, sorted, each with its type
        names."""

    def get_publishers_info_by_topic(self, topic: str) -> list[TopicEndpointInfo]:
        """Every publisher of ``topic`` in the graph, with its node, GID, type hash and QoS."""

    def count_publishers(self, topic: str) -> int:
        """How many publishers of ``topic`` the graph holds (what ``len`` of
        :meth:`get_publishers_info_by_topic` gives, for less)."""

    def get_subscriptions_info_by_topic(self, topic: str) -> list[TopicEndpointInfo]:
        """Every subscription of ``topic`` in the graph, with its node, GID, type hash and QoS."""

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        """``(name, namespace)`` of every node in the graph, sorted."""

    def get_service_names_and_types_by_node(
        self, node_name: str, node_namespace: str, server: bool = True
    ) -> list[tuple[str, list[str]]]:
        """The service servers (``server``) or clients of the node ``node_name`` in
        ``node_namespace``, sorted, each with its type names; none for a node not in the graph."""

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Wait at most ``timeout_sec`` [s] (None: until something is due) for a sample or a timer,
        then run the callbacks that are due. Returns at once after :func:`shutdown`."""

    def destroy_node(self) -> None:
        """Release every publisher, subscription and timer of the node and leave the graph."""


class ManagedNode(Node, Protocol):
    """A lifecycle node (``api.create_node(..., managed=True)``): rcl_lifecycle's states and
    transitions (:mod:`.lifecycle`), served on the ``lifecycle_msgs`` services."""

    def manage(self, on_transition: Callable[[str], str]) -> None:
        """Make ``on_transition`` the node's answer to each transition: it gets the transition's
        label and returns :data:`.lifecycle.SUCCESS`, ``FAILURE`` or ``ERROR``."""

    def lifecycle_state(self) -> str:
        """The label of the current primary state (``"unconfigured"``, ``"inactive"``, ``"active"``,
        ``"finalized"``)."""

    def trigger(self, transition: str) -> str:
        """Run the node's own ``transition`` (a label such as ``"configure"``) and return the
        outcome; raises :class:`~stillframe.middleware.lifecycle.TransitionRefusedError` when the
        current state has no such transition."""


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
    tens of milliseconds, a latency spike in the middle of a control loop. Objects made later are
    collected as usual."""
    global _gc_frozen
    if not _gc_frozen:
        gc.freeze()
        _gc_frozen = True
