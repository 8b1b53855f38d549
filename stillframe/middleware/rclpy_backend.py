"""The ``rclpy`` backend: the same node API over real rclpy, on workstations with ROS 2.

Messages stay ``rosbags`` instances: they are published as CDR bytes (rclpy publishes
serialized messages as they are) and subscriptions take CDR bytes (``raw=True`` in rclpy)
that ``rosbags`` decodes, so no message conversion code exists. rclpy parses ``--ros-args``
itself; signals are left to :mod:`.api` (rclpy's own handlers are not installed).
Raw subscriptions get the writer's source timestamp from the message info rcl takes with each
sample (Jazzy's carries no publisher GID, but the writer's publication sequence number).
"""

from __future__ import annotations

import array
import importlib
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import SetParametersResult as RclpySetParametersResult
from rclpy._rclpy_pybind11 import NodeNameNonExistentError, RCLError
from rclpy.clock import ClockType
from rclpy.duration import Duration
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    ReliabilityPolicy,
)
from rclpy.qos import QoSProfile as RclpyQoS
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions
from rosbags.typesys.base import Nodetype

from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.middleware import interface, lifecycle, param_messages, params
from stillframe.middleware.clock import SYSTEM_CLOCK, Clock, Time
from stillframe.middleware.params import Parameter, SetCallback
from stillframe.middleware.qos import (
    INFINITE_NS,
    Durability,
    History,
    Liveliness,
    QoSProfile,
    Reliability,
    as_profile,
)
from stillframe.middleware.rclpy_wait import (
    NEVER_EXECUTED,
    SUBSCRIPTIONS_WAITED_HERE,
    SubscriptionWait,
)

MAX_WAIT_S = 0.1


def ros_message_class(name: str) -> type:
    """rclpy's generated class of ``pkg/msg/Type`` or ``pkg/srv/Type``, imported from the
    installed interface package (what ``rosidl_runtime_py.utilities.get_message`` does; that
    package is not on PyPI)."""
    package, kind, type_name = name.split("/")
    try:
        return getattr(importlib.import_module(f"{package}.{kind}"), type_name)
    except (ImportError, AttributeError) as exc:
        raise InputError(
            f"message type {name!r}: not importable under rclpy "
            f"(pip install ros-jazzy-{package.replace('_', '-')})"
        ) from exc


def rclpy_qos(profile: QoSProfile) -> RclpyQoS:
    """rclpy's QoSProfile of ours (the enum values are rmw's in both)."""
    extra = {}
    for name in ("deadline", "lifespan", "liveliness_lease_duration"):
        ns = getattr(profile, name + "_ns")
        if ns < INFINITE_NS:
            extra[name] = Duration(nanoseconds=ns)
    return RclpyQoS(
        history=HistoryPolicy(int(profile.history)), depth=profile.depth,
        reliability=ReliabilityPolicy(int(profile.reliability)),
        durability=DurabilityPolicy(int(profile.durability)),
        liveliness=LivelinessPolicy(int(profile.liveliness)), **extra,
    )


def ros_qos(qos: RclpyQoS) -> QoSProfile:
    """Our QoSProfile of rclpy's."""
    def ns(duration: Duration) -> int:
        value = duration.nanoseconds
        return INFINITE_NS if value <= 0 or value >= INFINITE_NS else value

    return QoSProfile(
        history=History(int(qos.history)), depth=qos.depth,
        reliability=Reliability(int(qos.reliability)),
        durability=Durability(int(qos.durability)),
        deadline_ns=ns(qos.deadline), lifespan_ns=ns(qos.lifespan),
        liveliness=Liveliness(int(qos.liveliness)),
        liveliness_lease_duration_ns=ns(qos.liveliness_lease_duration),
    )


#: rclpy's message class of each range field of a descriptor
RANGE_CLASSES = {"floating_point_range": FloatingPointRange, "integer_range": IntegerRange}


def rclpy_descriptor(descriptor: params.ParameterDescriptor, default: Any) -> Any:
    """rclpy's ``ParameterDescriptor`` of ours, for a parameter of ``default``'s type (the
    fields of the message :func:`.param_messages.descriptor_msg` makes on the dds backend)."""
    ranges = {key: [RANGE_CLASSES[key](from_value=r.from_value, to_value=r.to_value,
                                       step=r.step) for r in value]
              for key, value in param_messages.range_fields(default, descriptor.range).items()}
    return ParameterDescriptor(description=descriptor.description,
                               additional_constraints=descriptor.additional_constraints,
                               read_only=descriptor.read_only, **ranges)


def plain_value(value: Any) -> Any:
    """A parameter value as our API holds it (rclpy gives arrays as ``array.array``)."""
    return list(value) if isinstance(value, array.array | tuple) else value


def rosbags_message(msg: Any, name: str) -> Any:
    """The ``rosbags`` message of an rclpy message, field by field (``serialize_message`` is
    no way round: its buffer can be longer than the CDR, which ``rosbags`` refuses)."""
    fields = {}
    for field, (kind, detail) in messages.fielddefs(name):
        value = getattr(msg, field)
        if kind == Nodetype.NAME:
            value = rosbags_message(value, detail)
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            sub_kind, sub_detail = detail[0]
            value = [rosbags_message(v, sub_detail) if sub_kind == Nodetype.NAME
                     else v[0] if isinstance(v, bytes) else v for v in value]
        fields[field] = value
    return messages.new(name, **fields)


class RclpyClock(Clock):
    """The node's rclpy clock (ROS time, sim time with ``use_sim_time``) as our Clock."""

    def __init__(self, clock: Any) -> None:
        super().__init__(sim=False)
        self._clock = clock

    def now(self) -> Time:
        """The clock's time as a :class:`~stillframe.middleware.clock.Time`."""
        return Time(self.now_ns())

    def now_ns(self) -> int:
        """The clock's time read from its rcl handle, as rclpy's ``Clock.now()`` reads it, but
        without building the ``rclpy.time.Time`` it returns, which costs more than the read
        itself (once per received sample)."""
        handle = self._clock.handle
        with handle:
            return handle.get_now().nanoseconds


def message_info(info: dict, clock: Clock) -> interface.MessageInfo:
    """A sample's info from rcl's: the writer's source timestamp, received now on the node's
    clock, the publisher's GID where rclpy gives it (Jazzy's does not) and the writer's
    publication sequence number (Jazzy's has it)."""
    return interface.MessageInfo(info["source_timestamp"], clock.now_ns(),
                                 bytes(info.get("publisher_gid") or b""),
                                 info.get("publication_sequence_number") or 0)


class RclpyPublisher:
    """:class:`.interface.Publisher` over an rclpy publisher of raw CDR."""

    def __init__(self, pub: Any, msg_type: str) -> None:
        self._pub = pub
        self.msg_type = msg_type
        self.topic_name = pub.topic_name

    def publish(self, msg: Any) -> None:
        """Publish a ``rosbags`` message (serialized here) or its CDR bytes through rclpy as raw
        bytes."""
        data = msg if isinstance(msg, bytes | bytearray) else messages.serialize(msg)
        self._pub.publish(bytes(data))

    def get_subscription_count(self) -> int:
        """rclpy's count of matched subscriptions."""
        return self._pub.get_subscription_count()

    def wait_for_all_acked(self, timeout_sec: float) -> bool:
        """rclpy's wait for every reliable reader's acknowledgement, at most ``timeout_sec`` [s]."""
        return self._pub.wait_for_all_acked(Duration(nanoseconds=int(timeout_sec * 1e9)))


class RclpyPolledSubscription:
    """:class:`.interface.PolledSubscription` over an rclpy subscription in
    :data:`NEVER_EXECUTED`; takes with rcl's ``take`` as the executor would."""

    def __init__(self, subscription: Any, clock: Any) -> None:
        self.subscription = subscription
        self.topic_name = subscription.topic_name
        self._clock = clock

    def take(self) -> list[tuple[bytes, interface.MessageInfo]]:
        """The samples waiting, each received at its arrival in rmw (``received_timestamp``,
        system time) moved onto the node's clock: one clock read per take, not per sample,
        and a sample taken late keeps the time it arrived."""
        taken = []
        now = self._clock.now_ns()
        offset = now - time.time_ns()
        with self.subscription.handle:
            while (got := self.subscription.handle.take_message(
                    self.subscription.msg_type, True)) is not None:
                info = got[1]
                arrived = info["received_timestamp"]
                taken.append((got[0], interface.MessageInfo(
                    info["source_timestamp"], min(arrived + offset, now) if arrived else now)))
        return taken


#: our callbacks' outcomes as rclpy's
RETURNS = {lifecycle.SUCCESS: TransitionCallbackReturn.SUCCESS,
           lifecycle.FAILURE: TransitionCallbackReturn.FAILURE,
           lifecycle.ERROR: TransitionCallbackReturn.ERROR}


class ManagedNode(LifecycleNode):
    """rclpy's ``LifecycleNode`` (its state machine, services and ``~/transition_event`` are
    rcl_lifecycle's) calling one :data:`.lifecycle.TransitionCallback`; a transition that is not
    available is refused with rcl_lifecycle's reason in the log, and the node goes on (rclpy
    7.1 lets the error out of the service callback, which ends the process)."""

    on_transition: lifecycle.TransitionCallback = staticmethod(lambda _: lifecycle.SUCCESS)

    def _answer(self, name: str) -> TransitionCallbackReturn:
        try:
            return RETURNS[self.on_transition(name)]
        except Exception as exc:
            self.get_logger().error(f"{name} failed: {exc}")
            return TransitionCallbackReturn.ERROR

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The ``configure`` transition, answered by :attr:`on_transition`."""
        return self._answer("configure")

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The ``cleanup`` transition, answered by :attr:`on_transition`."""
        return self._answer("cleanup")

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The ``shutdown`` transition, answered by :attr:`on_transition`."""
        return self._answer("shutdown")

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The ``activate`` transition, answered by :attr:`on_transition`."""
        return self._answer("activate")

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The ``deactivate`` transition, answered by :attr:`on_transition`."""
        return self._answer("deactivate")

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The ``error`` transition (a callback raised or answered error), answered by
        :attr:`on_transition`."""
        return self._answer("error")

    def _LifecycleNodeMixin__on_change_state(self, request: Any, response: Any) -> Any:  # noqa: N802
        """rclpy's change-state service, with a refused transition answered (success false,
        the reason logged as rclcpp logs it) instead of raised."""
        current = self._state_machine.current_state[1]
        transition = request.transition.label or request.transition.id
        available = {(t[0], t[1]) for t in self._state_machine.available_transitions}
        if not any(transition in pair for pair in available):
            self.get_logger().warning(
                f"Unable to start transition {transition} from current state {current}: "
                f"No transition matching {transition} found for current state {current}")
            response.success = False
            return response
        return LifecycleNode._LifecycleNodeMixin__on_change_state(self, request, response)


class RclpyNode:
    """:class:`.interface.Node` over an ``rclpy.node.Node`` (``managed``: rclpy's
    ``LifecycleNode``)."""

    backend = "rclpy"
    #: the process's wait (:mod:`.rclpy_wait`), beside rclpy's SingleThreadedExecutor
    _wait: SubscriptionWait | None = None

    def __init__(self, name: str, namespace: str, args: list[str], managed: bool = False) -> None:
        if not rclpy.ok():
            rclpy.init(args=["stillframe", *args], signal_handler_options=SignalHandlerOptions.NO)
        try:
            self._node = (ManagedNode(name, namespace=namespace) if managed
                          else rclpy.create_node(name, namespace=namespace))
        except RCLError as exc:
            reason = str(exc).splitlines()[0].removeprefix("error creating node: ")
            where = "ROS_STATIC_PEERS: " if "peer" in reason else ""
            raise InputError(f"{where}rcl cannot create node {name!r}: {reason}") from None
        self.user_args = rclpy.utilities.remove_ros_args(["stillframe", *args])[1:]
        self.malformed: Counter[str] = Counter()
        self._clock = RclpyClock(self._node.get_clock())
        if RclpyNode._wait is None:
            RclpyNode._wait = SubscriptionWait(SingleThreadedExecutor())
        RclpyNode._wait.add_node(self._node)

    def get_name(self) -> str:
        """rclpy's node name (after remapping)."""
        return self._node.get_name()

    def manage(self, on_transition: lifecycle.TransitionCallback) -> None:
        """The managed node's transition callbacks (it was created ``managed``)."""
        self._node.on_transition = on_transition

    def lifecycle_state(self) -> str:
        """The label of the managed node's current primary state, from rcl_lifecycle's state
        machine."""
        return self._node._state_machine.current_state[1]

    def trigger(self, transition: str) -> str:
        """Run the node's own ``transition`` (a label); the outcome; TransitionRefusedError if it is
        not available in the current state."""
        triggers = {"configure": self._node.trigger_configure,
                    "cleanup": self._node.trigger_cleanup,
                    "activate": self._node.trigger_activate,
                    "deactivate": self._node.trigger_deactivate,
                    "shutdown": self._node.trigger_shutdown}
        state = self.lifecycle_state()
        if transition not in {t[1] for t in self._node._state_machine.available_transitions}:
            raise lifecycle.TransitionRefusedError(
                f"No transition matching {transition} found for current state {state}")
        outcome = triggers[transition]()
        return {v: k for k, v in RETURNS.items()}[outcome]

    def get_namespace(self) -> str:
        """rclpy's node namespace (after remapping)."""
        return self._node.get_namespace()

    def get_logger(self) -> Any:
        """rclpy's node logger."""
        return self._node.get_logger()

    def get_clock(self) -> Clock:
        """The node's clock (:class:`RclpyClock`: ROS time, sim time with ``use_sim_time``)."""
        return self._clock

    def declare_parameter(
        self, name: str, default: Any = None, read_only: bool = False, *,
        descriptor: params.ParameterDescriptor | None = None,
    ) -> Parameter:
        """rclpy's declaration with the descriptor as rclpy's own (description, constraints,
        range, read-only). A start value outside the range is declared without the range, as
        the dds backend declares it: the caller checks the start value in its own words
        (:func:`stillframe.node_runtime.parameters.declare`), rclpy holds every later set to
        the range."""
        descriptor = params.described(descriptor, read_only=read_only)
        try:
            try:
                declared = self._node.declare_parameter(
                    name, default, rclpy_descriptor(descriptor, default))
            except InvalidParameterValueException:
                declared = self._node.declare_parameter(name, default, rclpy_descriptor(
                    replace(descriptor, range=None), default))
        except InvalidParameterTypeException as exc:     # an override of another type
            raise InputError(f"parameter {name!r} of node "
                             f"{self._node.get_fully_qualified_name()}: {exc.args[0]}") from None
        return Parameter(name, plain_value(declared.value))

    def get_parameter(self, name: str) -> Parameter:
        """The declared parameter ``name``, its value as a plain Python value (lists, not
        arrays)."""
        return Parameter(name, plain_value(self._node.get_parameter(name).value))

    def add_on_set_parameters_callback(self, callback: SetCallback) -> None:
        """rclpy's own callback (it checks declared, read-only and type first)."""
        def on_set(parameters: list[Any]) -> RclpySetParametersResult:
            result = callback([Parameter(p.name, plain_value(p.value)) for p in parameters])
            return RclpySetParametersResult(successful=result.successful, reason=result.reason)

        self._node.add_on_set_parameters_callback(on_set)

    def call_service(self, srv_type: str, service: str, request: Any,
                     timeout_sec: float, *, give_up: Callable[[], bool] | None = None,
                     ) -> Any | None:
        """Call ``service`` with rclpy's own client; the ``rosbags`` request and response
        cross as CDR. None if the service did not appear or answer within ``timeout_sec``, or
        once ``give_up()`` holds while the reply is awaited (checked every
        :data:`.interface.GIVE_UP_CHECK_S`)."""
        srv_class = ros_message_class(srv_type)
        client = self._node.create_client(srv_class, service)
        try:
            if not client.wait_for_service(timeout_sec=timeout_sec):
                return None
            future = client.call_async(
                deserialize_message(messages.serialize(request), srv_class.Request))
            deadline = time.monotonic() + timeout_sec
            while not future.done() and (remaining := deadline - time.monotonic()) > 0 and not (
                    give_up and give_up()):
                RclpyNode._wait.executor.spin_until_future_complete(
                    future, timeout_sec=min(remaining, interface.GIVE_UP_CHECK_S))
            if not future.done():
                return None
            return rosbags_message(future.result(), f"{srv_type}_Response")
        finally:
            self._node.destroy_client(client)

    def create_publisher(
        self, msg_type: str | type, topic: str, qos: QoSProfile | str | int
    ) -> RclpyPublisher:
        """An :class:`RclpyPublisher` of ``msg_type`` on ``topic`` with rclpy's own QoS profile."""
        name = messages.type_name(msg_type)
        pub = self._node.create_publisher(
            ros_message_class(name), topic, rclpy_qos(as_profile(qos))
        )
        return RclpyPublisher(pub, name)

    def create_subscription(
        self, msg_type: str | type, topic: str, callback: Callable[..., None],
        qos: QoSProfile | str | int, raw: bool = False,
    ) -> Any:
        """An rclpy subscription taking raw CDR, waited on by the process's :mod:`.rclpy_wait`; the
        callback gets decoded ``rosbags`` messages, or ``(cdr, MessageInfo)`` when ``raw``."""
        name = messages.type_name(msg_type)

        def on_data(data: bytes, info: dict) -> None:
            if raw:
                callback(data, message_info(info, self._clock))
            else:
                interface.deliver(callback, data, name, topic, self.malformed)

        return self._node.create_subscription(
            ros_message_class(name), topic, on_data, rclpy_qos(as_profile(qos)),
            callback_group=SUBSCRIPTIONS_WAITED_HERE, raw=True)

    def create_polled_subscription(
        self, msg_type: str | type, topic: str, qos: QoSProfile | str | int,
    ) -> RclpyPolledSubscription:
        """An :class:`RclpyPolledSubscription`: an rclpy subscription that no executor ever runs."""
        name = messages.type_name(msg_type)
        sub = self._node.create_subscription(
            ros_message_class(name), topic, interface.never_called, rclpy_qos(as_profile(qos)),
            callback_group=NEVER_EXECUTED, raw=True)
        return RclpyPolledSubscription(sub, self._clock)

    def destroy_subscription(self, sub: Any) -> None:
        """Destroy ``sub`` (an rclpy subscription, or the one inside a polled subscription)."""
        self._node.destroy_subscription(getattr(sub, "subscription", sub))

    def create_timer(
        self, period_s: float, callback: Callable[[], None], clock: Clock | None = None
    ) -> Any:
        """rclpy's timer on the node's clock, or on the system clock when ``clock`` is
        :data:`~stillframe.middleware.clock.SYSTEM_CLOCK`."""
        rclpy_clock = rclpy.clock.Clock(clock_type=ClockType.SYSTEM_TIME) if (
            clock is SYSTEM_CLOCK) else None
        return self._node.create_timer(period_s, callback, clock=rclpy_clock)

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """rclpy's topics and types in the graph, sorted."""
        return sorted(self._node.get_topic_names_and_types())

    def _endpoints(self, topic: str, infos: list[Any]) -> list[interface.TopicEndpointInfo]:
        return [
            interface.TopicEndpointInfo(
                topic_name=self._node.resolve_topic_name(topic),
                topic_type=info.topic_type,
                topic_type_hash=str(getattr(info, "topic_type_hash", "")),
                endpoint_gid=bytes(info.endpoint_gid), qos_profile=ros_qos(info.qos_profile),
                node_name=info.node_name, node_namespace=info.node_namespace,
            )
            for info in infos
        ]

    def get_publishers_info_by_topic(self, topic: str) -> list[interface.TopicEndpointInfo]:
        """Every publisher of ``topic`` in the graph, from rclpy's endpoint info."""
        return self._endpoints(topic, self._node.get_publishers_info_by_topic(topic))

    def count_publishers(self, topic: str) -> int:
        """rcl's count: one C call, without building the endpoint list."""
        return self._node.count_publishers(topic)

    def get_subscriptions_info_by_topic(self, topic: str) -> list[interface.TopicEndpointInfo]:
        """Every subscription of ``topic`` in the graph, from rclpy's endpoint info."""
        return self._endpoints(topic, self._node.get_subscriptions_info_by_topic(topic))

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        """rclpy's ``(name, namespace)`` of every node in the graph, sorted."""
        return sorted(self._node.get_node_names_and_namespaces())

    def get_service_names_and_types_by_node(
        self, node_name: str, node_namespace: str, server: bool = True
    ) -> list[tuple[str, list[str]]]:
        """A node's service servers (``server``) or clients, as rclpy gives them; none for a
        node not in the graph (yet), as the dds backend answers."""
        query = (self._node.get_service_names_and_types_by_node if server
                 else self._node.get_client_names_and_types_by_node)
        try:
            found = query(node_name, node_namespace)
        except NodeNameNonExistentError:
            return []
        return sorted((name, list(types)) for name, types in found)

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Wait at most ``timeout_sec`` [s] for a sample or a timer of the process's nodes, then run
        what is due; returns at once after :func:`.interface.shutdown`."""
        if interface.ok():
            interface.freeze_setup_objects()
            wait = MAX_WAIT_S if timeout_sec is None else min(MAX_WAIT_S, max(0.0, timeout_sec))
            RclpyNode._wait.spin_once(round(wait * 1e9))

    def destroy_node(self) -> None:
        """Destroy the rclpy node; with the process's last node gone, shut rclpy down."""
        interface.node_destroyed(self)
        RclpyNode._wait.remove_node(self._node)
        self._node.destroy_node()
        if not RclpyNode._wait.executor.get_nodes():
            RclpyNode._wait = None
            rclpy.try_shutdown()
