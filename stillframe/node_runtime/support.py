"""What the three loop nodes share: the scene parameters, ``/diagnostics``, timing statistics and
waiting for the peers of the lock-step protocol (docs/nodes.md).

Every node reads the same scene (``scene``, ``overrides``) so that it builds the same plant,
estimator or controller as :func:`stillframe.loop.closed_loop.run_closed_loop`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from stillframe.config.scene import Scene, load_scene
from stillframe.contract import messages, topics
from stillframe.fidelity.auto_model import resolve_model
from stillframe.loop.writer_gate import same_node
from stillframe.middleware import api
from stillframe.middleware.graph import fqn
from stillframe.middleware.qos import (
    PROFILES,
    Durability,
    QoSProfile,
    Reliability,
    as_profile,
)
from stillframe.node_runtime.declarations import LoopParameterValues
from stillframe.node_runtime.parameters import declare

#: the topics from the estimator to the simulator, read best effort in real time
CONTROL_PATH = (topics.STATE_ESTIMATE, topics.TORQUE_CMD, topics.FORCE_CMD)
#: After the peers are matched, spin this long so that the other side of every match (the
#: remote writer's view) has caught up before the first sample (docs/nodes.md, start-up).
SETTLE_S = 0.25
#: How many samples the loop's own lock-step readers keep (KEEP_LAST): a flood from a stray
#: writer (refused by writer, stillframe/loop/writer_gate.py) must not push the loop's own
#: sample, estimate or command out of the queue before it is read; 1000 samples are 0.1 s of a
#: 10 kHz flood.
FLOOD_DEPTH = 1000
#: the node name of ``stillframe record`` (it subscribes every topic at once)
RECORDER_NODE = "stillframe_recorder"
OK, WARN, ERROR = 0, 1, 2
#: wall seconds without input after which a loop node reports its input stale (the simulator
#: stale or gone); a lock-step sample waits on its slowest peer, so it is well above a sample's
#: round trip on a loaded machine
STALE_INPUT_S = 2.0


@dataclass(frozen=True)
class LoopParameters:
    """The parameters every loop node declares."""

    scene: Scene
    mode: str
    diagnostics_period_s: float
    #: the run's token (docs/nodes.md, writer identity; "": none)
    run_token: str = ""

    @property
    def period(self) -> float:
        """The sample period [s]: one over the scene's ``sensors.rate_hz``."""
        return 1.0 / self.scene.sensors.rate_hz

    @property
    def lockstep(self) -> bool:
        """Whether the node runs in lock-step (``mode: lockstep``) rather than in real time."""
        return self.mode == "lockstep"

    @property
    def stale_input_s(self) -> float:
        """Wall seconds without input after which the estimator and controller report the
        simulator stale or gone: :data:`STALE_INPUT_S`, or five sample periods if longer."""
        return max(STALE_INPUT_S, 5 * self.period)

    def qos(self, spec: topics.TopicSpec) -> QoSProfile | str:
        """The contract's QoS, except that sensor topics are RELIABLE and TRANSIENT_LOCAL in
        lock-step.

        Lock-step promises the same numbers as the one-process loop; a best-effort sample lost
        under load would silently turn into a partial update. TRANSIENT_LOCAL closes the start:
        the simulator sees its writers matched before the estimator's reader has matched them
        (discovery is not symmetric), and a volatile Fast DDS reader then can skip the first
        sample a Cyclone writer sent, a lock-step timeout; a transient-local reader is handed it
        on matching. A reliable transient-local writer still matches the contract's best-effort
        volatile readers (``ros2 topic echo``, the recorder), so only the loop's own readers ask for
        more than the contract.
        """
        if self.lockstep and spec.qos == "sensor_data":
            return replace(PROFILES["sensor_data"], reliability=Reliability.RELIABLE,
                           durability=Durability.TRANSIENT_LOCAL)
        return spec.qos

    def reader_qos(self, spec: topics.TopicSpec) -> QoSProfile | str:
        """What the loop's own readers ask for: :meth:`qos`, read :data:`FLOOD_DEPTH` deep in
        lock-step, and in real time with the control path (:data:`CONTROL_PATH`: estimates and
        commands) read BEST_EFFORT.

        The writers stay RELIABLE as the contract says (a recorder or a viewer still gets every
        sample), but a real-time loop has no use for a sample that comes late: a reliable reader
        delivers in order, so one lost packet holds back every later estimate or command until
        the retransmission (after the writer's next heartbeat and the reader's NACK, tens of
        ms), and the loop then acts on old data. Read best effort, a lost estimate or command is
        one missed period: the simulator holds the last command (its command timeout brings the
        safe state), the controller answers the next estimate (docs/reliability.md)."""
        if self.lockstep:
            return as_profile(self.qos(spec)).with_depth(FLOOD_DEPTH)
        if spec in CONTROL_PATH:
            return replace(as_profile(spec.qos), reliability=Reliability.BEST_EFFORT)
        return spec.qos


def declare_loop_parameters(node: api.Node) -> LoopParameters:
    """The parameters every loop node declares (:class:`.declarations.LoopParameterValues`,
    InputError naming a wrong one), with the scene loaded and its model resolved."""
    values = declare(node, LoopParameterValues)
    scene, _ = resolve_model(load_scene(values.scene, [v for v in values.overrides if v]))
    return LoopParameters(scene, values.mode, values.diagnostics_period_s, values.run_token)


def malformed_samples(node: api.Node) -> int:
    """The samples that did not decode: those ``node``'s subscriptions dropped, and those
    Cyclone dropped in this process before any node saw them (:mod:`.cyclone_log`)."""
    return sum(node.malformed.values()) + sum(api.CYCLONE_DROPPED.values())


class Diagnostics:
    """One ``diagnostic_msgs/DiagnosticStatus`` per node on ``/diagnostics``: the node publishes
    one when :meth:`due` says ``period_s`` of wall time have passed and the next sample leaves
    time for it, when it has news of its own (a writer gate's) and a last one when it finishes.

    A status takes a node hundreds of microseconds (its values, the message, the write): in real
    time it waits for a turn whose time before the next sample holds what the last one took
    (:attr:`cost_ns`), the way the collector's work does (:meth:`.realtime.Realtime.idle`), but
    never more than one more ``period_s``.
    """

    def __init__(self, node: api.Node, period_s: float) -> None:
        self.pub = node.create_publisher(topics.DIAGNOSTICS.type_name, topics.DIAGNOSTICS.name,
                                         topics.DIAGNOSTICS.qos)
        self.node = node
        self.name = f"{node.get_namespace().rstrip('/')}/{node.get_name()}"
        self.period_s = period_s
        self.next = time.monotonic() + period_s
        #: what the last status took from :meth:`due` saying yes to its write [ns]
        self.cost_ns = 0
        #: statuses that waited for a turn with time enough before the next sample
        self.deferred = 0
        self._waiting = False
        self._asked_ns: int | None = None

    def due(self, slack_ns: int | None = None) -> bool:
        """Whether to publish a status now: ``period_s`` of wall time has passed since the last
        (or since the start), and ``slack_ns`` (the time left before the next sample; None: no
        deadline) holds :attr:`cost_ns` or the status is a whole period late."""
        now = time.monotonic()
        if now < self.next:
            return False
        if slack_ns is not None and slack_ns < self.cost_ns and now < self.next + self.period_s:
            self.deferred += not self._waiting
            self._waiting = True
            return False
        self._waiting = False
        self._asked_ns = time.monotonic_ns()
        return True

    def publish(self, stamp_ns: int, values: dict[str, Any], level: int = OK,
                message: str = "") -> None:
        """Publish one status stamped ``stamp_ns`` with ``values`` (each float as ``%.6g`` text) and
        the samples that did not decode, at ``level`` with ``message`` ("OK" or "degraded" when
        empty); the next is due ``period_s`` later."""
        kv = messages.msg_class("diagnostic_msgs/msg/KeyValue")
        values = {**values, "malformed_samples": malformed_samples(self.node),
                  "statuses_deferred": self.deferred}
        status = messages.new(
            "diagnostic_msgs/msg/DiagnosticStatus", level=level, name=self.name,
            message=message or ("OK" if level == OK else "degraded"), hardware_id="stillframe",
            values=[kv(key=k, value=_text(v)) for k, v in values.items()],
        )
        array = messages.new("diagnostic_msgs/msg/DiagnosticArray", status=[status])
        array.header.stamp = messages.time_msg(stamp_ns)
        self.pub.publish(array)
        self.next = time.monotonic() + self.period_s
        if self._asked_ns is not None:
            self.cost_ns, self._asked_ns = time.monotonic_ns() - self._asked_ns, None


def _text(value: Any) -> str:
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def diagnostic_values(msg: Any) -> dict[str, str]:
    """The key/value pairs of the first status of a DiagnosticArray (for tools and tests)."""
    return {kv.key: kv.value for kv in msg.status[0].values} if msg.status else {}


class RateMeter:
    """Events per second of wall time since the last reading."""

    def __init__(self) -> None:
        self.count = 0
        self.since = time.monotonic()

    def tick(self) -> None:
        """Count one event."""
        self.count += 1

    def read(self) -> float:
        """Events per second since the last reading (or the start), and start counting again."""
        now = time.monotonic()
        rate = self.count / max(now - self.since, 1e-9)
        self.count, self.since = 0, now
        return rate


def wait_for_peers(node: api.Node, ready: Callable[[], bool],
                   timeout_s: float = math.inf) -> bool:
    """Spin until ``ready()`` (then :data:`SETTLE_S` more); False after ``timeout_s`` (default:
    no limit) or on shutdown."""
    deadline = time.monotonic() + timeout_s
    while not api.spin_until(node, ready, max(0.0, min(1.0, deadline - time.monotonic()))):
        if not api.ok() or time.monotonic() >= deadline:
            return False
    api.spin_until(node, lambda: False, SETTLE_S)
    return api.ok()


def has_publisher(node: api.Node, topic: str, peer: str) -> bool:
    """The graph shows a publisher of ``topic`` in node ``peer`` (a relative name in ``node``'s
    namespace; the reader side of a match)."""
    return any(same_node(fqn(ep.node_namespace, ep.node_name), peer, node.get_namespace())
               for ep in node.get_publishers_info_by_topic(topic))


def has_subscriber(node: api.Node, topic: str, peer: str) -> bool:
    """The graph shows a subscription of ``topic`` in node ``peer`` (a relative name in
    ``node``'s namespace; the writer side of a match)."""
    return any(same_node(fqn(ep.node_namespace, ep.node_name), peer, node.get_namespace())
               for ep in node.get_subscriptions_info_by_topic(topic))


def reaches_peer(node: api.Node, publisher: api.Publisher, peer: str) -> bool:
    """``publisher`` has matched every subscription of its topic the graph shows, and one of them
    belongs to node ``peer`` (``name`` in ``node``'s namespace, or ``/namespace/name``).

    A matched count alone is not enough in lock-step, nor is any named node: the recorder
    subscribes every topic at once and can match before the peer does; a tool's idle publisher
    on the command topic can do the same for the simulator's reader. The loop would then start
    before the peer's side had matched, and lose the first command (a lock-step timeout)."""
    return _matched_with_peer(node, node.get_subscriptions_info_by_topic(publisher.topic_name),
                              publisher.get_subscription_count(), peer)


def hears_peer(node: api.Node, subscription: api.Subscription, peer: str) -> bool:
    """``subscription`` has matched every publisher of its topic the graph shows, one of them in
    node ``peer`` (the reader's side of :func:`reaches_peer`)."""
    return _matched_with_peer(node, node.get_publishers_info_by_topic(subscription.topic_name),
                              subscription.get_publisher_count(), peer)


def _matched_with_peer(node: api.Node, remote: list[api.TopicEndpointInfo], matched: int,
                       peer: str) -> bool:
    """Every remote endpoint matched, one of them in node ``peer`` (resolved in ``node``'s
    namespace: a ``controller_node`` in another namespace is not the loop's)."""
    return matched >= len(remote) and any(
        same_node(fqn(ep.node_namespace, ep.node_name), peer, node.get_namespace())
        for ep in remote)
