"""The ``dds`` backend: the node API over Eclipse Cyclone DDS with ROS 2's wire conventions.

What a Jazzy workstation (``rmw_cyclonedds_cpp``) expects, see docs/middleware.md:
``rt/`` topics and ``pkg::msg::dds_::Type_`` types (:mod:`.dds_types`), participant USER_DATA
``enclave=/;``, endpoint USER_DATA ``typehash=RIHS01_<hex>;``, and the node list on
``ros_discovery_info`` (``rmw_dds_common/msg/ParticipantEntitiesInfo``; GIDs are the DDS
GUIDs). Samples are CDR from ``rosbags`` written as-is (padded to 4 bytes, as Cyclone pads);
the registered struct type describes exactly those bytes (checked by the tests).

One DDS participant per process and domain (as rmw does per context) carries every node of
the process. ``ROS_DOMAIN_ID`` selects the domain; ``ROS_AUTOMATIC_DISCOVERY_RANGE``,
``ROS_STATIC_PEERS`` and ``CYCLONEDDS_URI`` configure discovery as for rmw_cyclonedds_cpp
(:mod:`.discovery`).
"""

from __future__ import annotations

import itertools
import time
from collections import Counter
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsParticipant,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.core import (
    DDSException,
    DDSStatus,
    InstanceState,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.middleware import dds_types, discovery, interface, intra_process, names, params
from stillframe.middleware.clock import Clock
from stillframe.middleware.cyclone_raw import (
    ANY_SAMPLES,
    attach,
    attach_key,
    key_slots,
    matched_count,
    take_raw,
    wait_triggered,
    write_raw,
    writer_guid,
)
from stillframe.middleware.logger import Logger
from stillframe.middleware.qos import (
    CLOCK,
    INFINITE_NS,
    Durability,
    History,
    Liveliness,
    QoSProfile,
    Reliability,
    as_profile,
)

DISCOVERY_TOPIC = "ros_discovery_info"
DISCOVERY_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
#: Longest single wait inside ``spin_once``, so that signals are handled promptly.
MAX_WAIT_NS = 100_000_000
#: Samples taken from one reader per ``spin_once``.
TAKE_BATCH = 256
#: builtin-topic samples read per call
GRAPH_BATCH = 64
#: builtin-topic samples not read yet, of alive entities and of vanished ones
_NEW_ALIVE = SampleState.NotRead | ViewState.Any | InstanceState.Alive
_NEW_GONE = (SampleState.NotRead | ViewState.Any | InstanceState.NotAliveDisposed
             | InstanceState.NotAliveNoWriters)
_RELIABLE_BLOCKING_NS = 100_000_000  # rmw_cyclonedds' max_blocking_time


def dds_qos(profile: QoSProfile, user_data: bytes | None = None, writer: bool = True) -> Qos:
    """Cyclone QoS of an rmw profile (XCDR1; unset SYSTEM_DEFAULT/infinite policies left out)."""
    policies: list[Any] = [Policy.DataRepresentation(use_cdrv0_representation=True)]
    if profile.reliability == Reliability.RELIABLE:
        policies.append(Policy.Reliability.Reliable(max_blocking_time=_RELIABLE_BLOCKING_NS))
    elif profile.reliability == Reliability.BEST_EFFORT:
        policies.append(Policy.Reliability.BestEffort)
    if profile.history == History.KEEP_LAST:
        policies.append(Policy.History.KeepLast(depth=profile.depth))
    elif profile.history == History.KEEP_ALL:
        policies.append(Policy.History.KeepAll)
    if profile.durability == Durability.TRANSIENT_LOCAL:
        policies.append(Policy.Durability.TransientLocal)
    elif profile.durability == Durability.VOLATILE:
        policies.append(Policy.Durability.Volatile)
    if profile.deadline_ns < INFINITE_NS:
        policies.append(Policy.Deadline(deadline=profile.deadline_ns))
    if writer and profile.lifespan_ns < INFINITE_NS:
        policies.append(Policy.Lifespan(lifespan=profile.lifespan_ns))
    if profile.liveliness == Liveliness.MANUAL_BY_TOPIC:
        policies.append(Policy.Liveliness.ManualByTopic(profile.liveliness_lease_duration_ns))
    elif profile.liveliness_lease_duration_ns < INFINITE_NS:
        policies.append(Policy.Liveliness.Automatic(profile.liveliness_lease_duration_ns))
    if user_data is not None:
        policies.append(Policy.Userdata(data=user_data))
    return Qos(*policies)


def ros_qos(qos: Qos) -> QoSProfile:
    """The rmw profile of a discovered endpoint's Cyclone QoS."""
    def get(policy: Any) -> Any:
        return qos[policy] if policy in qos else None  # noqa: SIM401 - Qos has no .get

    history = get(Policy.History)
    reliability = get(Policy.Reliability)
    durability = get(Policy.Durability)
    liveliness = get(Policy.Liveliness)
    deadline = get(Policy.Deadline)
    lifespan = get(Policy.Lifespan)

    def duration(value: int | None) -> int:
        return INFINITE_NS if value is None or value >= INFINITE_NS else value

    return QoSProfile(
        history=History.KEEP_ALL if history == Policy.History.KeepAll else History.KEEP_LAST,
        depth=getattr(history, "depth", 0) if history != Policy.History.KeepAll else 0,
        reliability=(Reliability.BEST_EFFORT if reliability == Policy.Reliability.BestEffort
                     else Reliability.RELIABLE),
        durability=(Durability.TRANSIENT_LOCAL if durability == Policy.Durability.TransientLocal
                    else Durability.VOLATILE),
        deadline_ns=duration(getattr(deadline, "deadline", None)),
        lifespan_ns=duration(getattr(lifespan, "lifespan", None)),
        liveliness=(Liveliness.MANUAL_BY_TOPIC
                    if isinstance(liveliness, Policy.Liveliness.ManualByTopic)
                    else Liveliness.AUTOMATIC),
        liveliness_lease_duration_ns=duration(getattr(liveliness, "lease_duration", None)),
    )


def user_data_field(qos: Qos, key: str) -> str:
    """The value of ``key=value;`` in an entity's USER_DATA ('' if absent)."""
    data = qos[Policy.Userdata].data if Policy.Userdata in qos else b""
    for item in data.decode("utf-8", "replace").split(";"):
        name, _, value = item.partition("=")
        if name == key:
            return value
    return ""


def delete(entity: Any) -> None:
    """Delete a Cyclone entity now (and its children) instead of at garbage collection."""
    if entity is not None:
        entity.__del__()


class Context:
    """The process's participant in one domain, shared by its nodes; publishes the node list."""

    _instances: ClassVar[dict[int, Context]] = {}

    @classmethod
    def get(cls) -> Context:
        """The participant of the domain that ``ROS_DOMAIN_ID`` names, made on first use."""
        domain = discovery.domain_id()
        if domain not in cls._instances:
            cls._instances[domain] = cls(domain)
        return cls._instances[domain]

    def __init__(self, domain: int) -> None:
        self.domain_id = domain
        config = discovery.cyclone_config()
        try:
            self.domain = Domain(domain, config) if config else None
            self.participant = DomainParticipant(domain,
                                                 qos=Qos(Policy.Userdata(data=b"enclave=/;")))
        except DDSException as exc:     # the configuration: the user's, or the variables'
            source = "CYCLONEDDS_URI" if discovery.value("CYCLONEDDS_URI") else \
                "the discovery variables"
            raise InputError(f"Cyclone DDS refuses the configuration of {source} (domain "
                             f"{domain}): {str(exc).splitlines()[0]}") from None
        self.gid = self.participant.guid.bytes
        self.nodes: list[DdsNode] = []
        self.topics: dict[str, Topic] = {}
        discovery_qos = QoSProfile(depth=1, durability=Durability.TRANSIENT_LOCAL)
        self._discovery_writer = DataWriter(
            self.participant, self.topic(DISCOVERY_TOPIC, DISCOVERY_TYPE), dds_qos(discovery_qos)
        )
        #: per kind of builtin topic: its reader, and conditions for the samples not read yet
        #: of alive and of vanished entities
        self._graph_readers: dict[str, tuple[BuiltinDataReader, ReadCondition,
                                             ReadCondition]] = {}
        #: per kind, the alive entities by key, kept up to date by each read
        self._graph_known: dict[str, dict[Any, Any]] = {}
        #: per kind, the alive samples of the last read (read again only after a change) and
        #: how many reads that was
        self._graph_samples: dict[str, tuple[int, list[Any]]] = {}
        #: per kind, (read count, owners) the endpoints were made from, and the endpoints
        self._endpoints: dict[str, tuple[tuple[int, dict], list[interface.TopicEndpointInfo]]] = {}
        self._discovery_reader: DataReader | None = None
        self._participant_nodes: dict[bytes, list[Any]] = {}

    def topic(self, dds_name: str, ros_type: str, request_header: bool = False) -> Topic:
        """The Cyclone topic ``dds_name`` of type ``ros_type`` (one per name and participant;
        ``request_header``: a service's request or reply topic)."""
        existing = self.topics.get(dds_name)
        struct = dds_types.idl_struct(ros_type, request_header)
        if existing is not None:
            if existing.data_type is not struct:
                raise InputError(
                    f"topic {dds_name!r} is already used with type "
                    f"{dds_types.ros_type(existing.data_type.__idl_typename__)}, not {ros_type}"
                )
            return existing
        try:
            self.topics[dds_name] = Topic(self.participant, dds_name, struct)
        except DDSException as exc:
            raise InputError(f"cannot create topic {dds_name!r} ({ros_type}): {exc}") from exc
        return self.topics[dds_name]

    def publish_graph(self) -> None:
        """Publish every node of this participant with its reader and writer GIDs."""
        gid = messages.msg_class("rmw_dds_common/msg/Gid")
        info = messages.new(
            DISCOVERY_TYPE,
            gid=gid(data=_gid_array(self.gid)),
            node_entities_info_seq=[
                messages.new(
                    "rmw_dds_common/msg/NodeEntitiesInfo",
                    node_namespace=node.get_namespace(),
                    node_name=node.get_name(),
                    reader_gid_seq=[gid(data=_gid_array(g)) for g in node.reader_gids()],
                    writer_gid_seq=[gid(data=_gid_array(g)) for g in node.writer_gids()],
                )
                for node in self.nodes
            ],
        )
        write_raw(self._discovery_writer, messages.serialize(info))

    def remove_node(self, node: DdsNode) -> None:
        """Drop ``node`` from the published node list; with the last node gone, delete the
        participant."""
        self.nodes.remove(node)
        if self.nodes:
            self.publish_graph()
            return
        delete(self.participant)
        delete(self.domain)
        del Context._instances[self.domain_id]

    # -- graph ----------------------------------------------------------------------------
    def _alive(self, kind: str) -> tuple[int, list[Any]]:
        """How many reads so far, and the alive samples of a builtin topic. Read only when the
        reader has data available (a new, changed or vanished entity; a read resets that
        status), and then only the samples not read before: cyclonedds converts each
        endpoint's QoS in Python, and reading every endpoint of a running loop on each call
        would cost a node that asks the graph inside its loop a late sample. A vanished
        entity comes as a not-read sample of a not-alive instance, by its key."""
        if kind not in self._graph_readers:
            builtin = {
                "participant": BuiltinTopicDcpsParticipant,
                "publication": BuiltinTopicDcpsPublication,
                "subscription": BuiltinTopicDcpsSubscription,
            }[kind]
            reader = BuiltinDataReader(self.participant, builtin)
            self._graph_readers[kind] = (reader, ReadCondition(reader, _NEW_ALIVE),
                                         ReadCondition(reader, _NEW_GONE))
            self._graph_known[kind] = {}
        reader, fresh, gone = self._graph_readers[kind]
        if kind not in self._graph_samples or (
                reader.get_status_changes() & DDSStatus.DataAvailable):
            known = self._graph_known[kind]
            for sample in _read_all(reader, gone):
                known.pop(sample.key, None)
            for sample in _read_all(reader, fresh):
                known[sample.key] = sample
            reads = self._graph_samples.get(kind, (0, []))[0] + 1
            self._graph_samples[kind] = (reads, list(known.values()))
        return self._graph_samples[kind]

    def node_names(self) -> dict[bytes, list[tuple[str, str, set[bytes]]]]:
        """Per alive participant GID: its nodes as (namespace, name, endpoint GIDs)."""
        if self._discovery_reader is None:
            qos = QoSProfile(depth=1000, durability=Durability.TRANSIENT_LOCAL)
            topic = self.topic(DISCOVERY_TOPIC, DISCOVERY_TYPE)
            self._discovery_reader = DataReader(self.participant, topic, dds_qos(qos, writer=False))
        for data, sample in take_raw(self._discovery_reader, 100_000):
            if sample.valid_data:
                info = messages.deserialize(data, DISCOVERY_TYPE)
                self._participant_nodes[bytes(info.gid.data)] = [
                    (n.node_namespace, n.node_name,
                     {bytes(g.data) for g in (*n.reader_gid_seq, *n.writer_gid_seq)})
                    for n in info.node_entities_info_seq
                ]
        alive = {p.key.bytes for p in self._alive("participant")[1]}
        return {gid: nodes for gid, nodes in self._participant_nodes.items() if gid in alive}

    def endpoints(self, kind: str) -> list[interface.TopicEndpointInfo]:
        """Every alive ROS publisher (``kind='publication'``) or subscription on the network."""
        owners = {
            gid: (namespace, name)
            for nodes in self.node_names().values()
            for namespace, name, gids in nodes
            for gid in gids
        }
        reads, samples = self._alive(kind)
        made_from, made = self._endpoints.get(kind, ((0, {}), []))
        if made_from == (reads, owners):
            return made
        result = []
        for ep in samples:
            topic, rtype = dds_types.ros_topic(ep.topic_name), dds_types.ros_type(ep.type_name)
            if topic is None or rtype is None:
                continue
            namespace, name = owners.get(ep.key.bytes, ("", ""))
            result.append(interface.TopicEndpointInfo(
                topic_name=topic, topic_type=rtype,
                topic_type_hash=user_data_field(ep.qos, "typehash"),
                endpoint_gid=ep.key.bytes, qos_profile=ros_qos(ep.qos),
                node_name=name, node_namespace=namespace,
            ))
        self._endpoints[kind] = ((reads, owners), result)
        return result

    def services(self, kind: str) -> list[tuple[str, str, str, str]]:
        """(node namespace, node name, service, type) of every alive request reader
        (``kind='subscription'``: a service server) or request writer (a client)."""
        owners = {gid: (namespace, name) for nodes in self.node_names().values()
                  for namespace, name, gids in nodes for gid in gids}
        found = []
        for ep in self._alive(kind)[1]:
            service, rtype = dds_types.ros_service(ep.topic_name), dds_types.ros_type(ep.type_name)
            if service is not None and rtype is not None and ep.key.bytes in owners:
                found.append((*owners[ep.key.bytes], service, rtype))
        return found


def _read_all(reader: BuiltinDataReader, condition: ReadCondition) -> list[Any]:
    """Every sample ``condition`` selects, read :data:`GRAPH_BATCH` at a time (cyclonedds
    allocates room for as many samples as asked for on every read)."""
    found: list[Any] = []
    while True:
        batch = reader.read(N=GRAPH_BATCH, condition=condition)
        found += batch
        if len(batch) < GRAPH_BATCH:
            return found


def _gid_array(gid: bytes) -> Any:
    return np.frombuffer(gid.ljust(16, b"\0")[:16], dtype=np.uint8).copy()


class DdsPublisher:
    """A ROS publisher: ``publish`` a message of its type, or CDR bytes."""

    def __init__(self, node: DdsNode, ros_type: str, topic: str, qos: QoSProfile) -> None:
        self.topic_name = topic
        self.msg_type = ros_type
        self.qos_profile = qos
        user_data = f"typehash={messages.type_hash(ros_type)};".encode()
        self._writer = DataWriter(
            node.context.participant,
            node.context.topic(dds_types.dds_topic(topic), ros_type),
            dds_qos(qos, user_data),
        )
        self.gid = self._writer.guid.bytes
        messages.prepare(ros_type)
        #: the process's raw subscriptions of this topic (:mod:`.intra_process`; usually none)
        self._local = intra_process.subscriptions(topic)
        intra_process.add_publisher(topic)

    def publish(self, msg: Any) -> None:
        """Publish a ``rosbags`` message of this publisher's type, or its CDR bytes (written as
        they are: a preallocated ``bytearray`` is not copied), and hand the bytes to the
        process's own subscriptions of the topic (:mod:`.intra_process`)."""
        if isinstance(msg, memoryview):
            msg = bytes(msg)
        elif not isinstance(msg, bytes | bytearray):
            if getattr(msg, "__msgtype__", None) != self.msg_type:
                raise InputError(
                    f"publisher on {self.topic_name} takes {self.msg_type}, "
                    f"got {getattr(msg, '__msgtype__', type(msg).__name__)}"
                )
            msg = messages.serialize(msg)
        write_raw(self._writer, msg)
        if self._local:
            cdr, now = bytes(msg), time.time_ns()
            for deliver in self._local:
                deliver(cdr, now, self.gid)

    def release(self) -> None:
        """Delete the writer."""
        intra_process.remove_publisher(self.topic_name)
        delete(self._writer)

    def get_subscription_count(self) -> int:
        """Matched readers, the process's own subscriptions of the topic included."""
        return matched_count(self._writer) + intra_process.subscription_count(self.topic_name)

    def wait_for_all_acked(self, timeout_sec: float) -> bool:
        """Block until every reliable reader acknowledged everything (True) or the timeout."""
        return bool(self._writer.wait_for_acks(int(timeout_sec * 1e9)))


class DdsSubscription:
    """A ROS subscription; its callback gets messages, or ``(cdr, MessageInfo)`` when raw."""

    def __init__(
        self, node: DdsNode, ros_type: str, topic: str,
        callback: Callable[..., None], qos: QoSProfile, raw: bool, intra: bool = False,
    ) -> None:
        self.topic_name = topic
        self.msg_type = ros_type
        self.qos_profile = qos
        self.raw = raw
        self.callback = callback
        self.malformed = node.malformed
        #: the process's own writers hand their samples over (:mod:`.intra_process`) and the
        #: reader ignores them
        self.intra = intra
        user_data = f"typehash={messages.type_hash(ros_type)};".encode()
        reader_qos = dds_qos(qos, user_data, writer=False)
        if intra:
            reader_qos += Qos(Policy.IgnoreLocal.Participant)
            intra_process.subscribe(topic, self.deliver_local)
        self._reader = DataReader(
            node.context.participant,
            node.context.topic(dds_types.dds_topic(topic), ros_type),
            reader_qos,
        )
        self.condition = ReadCondition(self._reader, ANY_SAMPLES)
        self.gid = self._reader.guid.bytes
        self._writer_gids: dict[int, bytes] = {}
        messages.prepare(ros_type)
        self._clock = node.get_clock()

    def get_publisher_count(self) -> int:
        """Matched writers, the process's own publishers of the topic included when they hand
        their samples over."""
        local = intra_process.publisher_count(self.topic_name) if self.intra else 0
        return matched_count(self._reader) + local

    def release(self) -> None:
        """Delete the reader."""
        if self.intra:
            intra_process.unsubscribe(self.topic_name, self.deliver_local)
        delete(self._reader)

    def deliver_local(self, cdr: bytes, source_timestamp: int, gid: bytes) -> None:
        """A sample written in this process (:mod:`.intra_process`), received now."""
        self.callback(cdr, interface.MessageInfo(source_timestamp, self._clock.now_ns(), gid))

    def writer_gid(self, handle: int) -> bytes:
        """The GUID of the matched writer with instance handle ``handle`` (empty if gone)."""
        if handle not in self._writer_gids:
            guid = writer_guid(self._reader, handle)
            if guid is None:
                return b""
            self._writer_gids[handle] = guid
        return self._writer_gids[handle]

    def _taken(self) -> list[tuple[Any, Any]]:
        """The samples with data waiting (at most ``TAKE_BATCH``), oldest first."""
        return [(data, info) for data, info in take_raw(self._reader, TAKE_BATCH)
                if info.valid_data]

    def _info(self, info: Any) -> interface.MessageInfo:
        """A raw sample's info, received now."""
        return interface.MessageInfo(info.source_timestamp, self._clock.now_ns(),
                                     self.writer_gid(info.publication_handle))

    def take(self) -> list[tuple[bytes, interface.MessageInfo]]:
        """The samples waiting, raw with their info, oldest first (polled subscriptions). Cyclone
        keeps no reception time, so each is received at its source time stamp (the writer's
        clock; on one host the system clock) moved onto the node's clock, never later than
        now: one clock read per take, and a sample taken late keeps the time it was sent."""
        now = self._clock.now_ns()
        offset = now - time.time_ns()
        return [(bytes(data), interface.MessageInfo(
                    info.source_timestamp, min(info.source_timestamp + offset, now),
                    self.writer_gid(info.publication_handle)))
                for data, info in self._taken()]

    def take_and_dispatch(self) -> int:
        """Hand every waiting sample to the callback; the number handed."""
        samples = self._taken()
        for data, info in samples:
            if self.raw:
                self.callback(bytes(data), self._info(info))
            else:
                interface.deliver(self.callback, data, self.msg_type, self.topic_name,
                                  self.malformed)
        return len(samples)


class DdsTimer:
    """Calls back every period on a clock; with sim time it starts at the first ``/clock``
    and, like rcl, skips periods it fell behind on instead of firing a burst."""

    def __init__(self, period_s: float, callback: Callable[[], None], clock: Clock) -> None:
        if not period_s > 0:
            raise InputError(f"timer period must be > 0 s, got {period_s}")
        self.period_ns = round(period_s * 1e9)
        self.callback = callback
        self.clock = clock
        self.canceled = False
        self.next_ns: int | None = None
        self.reset()

    def reset(self) -> None:
        """Start the period from now on the timer's clock (not before the first ``/clock`` with sim
        time)."""
        self.canceled = False
        self.next_ns = self.clock.now().nanoseconds + self.period_ns if self.clock.started else None

    def cancel(self) -> None:
        """Stop calling back until :meth:`reset`."""
        self.canceled = True

    def time_until_call_ns(self) -> int | None:
        """Nanoseconds until the next call (≤ 0: due now), or None when canceled or before sim time
        starts."""
        if self.canceled or not self.clock.started:
            return None
        if self.next_ns is None:
            self.reset()
        return self.next_ns - self.clock.now().nanoseconds

    def call_if_due(self) -> bool:
        """Call back if the period elapsed and move to the next period not in the past (skipped
        periods are not made up); True if it called."""
        wait = self.time_until_call_ns()
        if wait is None or wait > 0:
            return False
        now = self.clock.now().nanoseconds
        self.next_ns += self.period_ns
        if self.next_ns <= now:
            self.next_ns = now + self.period_ns - (now - self.next_ns) % self.period_ns
        self.callback()
        return True


class DdsNode:
    """A ROS node on the process's Cyclone participant (API: :class:`.interface.Node`)."""

    backend = "dds"

    def __init__(self, name: str, namespace: str, args: list[str]) -> None:
        ros_args = params.parse_ros_args(args)
        remapped = {src: dst for node, src, dst in ros_args.remaps if node in (None, name)}
        self._name = names.validate_node_name(remapped.pop("__node", remapped.pop("__name", name)))
        self._namespace = names.validate_namespace(remapped.pop("__ns", namespace))
        self._remaps = {
            names.resolve_topic(src, self._namespace, self._name):
            names.resolve_topic(dst, self._namespace, self._name)
            for src, dst in remapped.items()
        }
        fqn = self._namespace.rstrip("/") + "/" + self._name
        self._logger = Logger(fqn.lstrip("/").replace("/", "."), ros_args.log_level or "info")
        self._params = params.Parameters(fqn, params.node_overrides(ros_args, fqn))
        self.user_args = ros_args.user_args
        self.context = Context.get()
        self.malformed: Counter[str] = Counter()
        self._publishers: list[DdsPublisher] = []
        self._subscriptions: list[DdsSubscription] = []
        self._polled: list[DdsSubscription] = []    # readers outside the wait set
        self._timers: list[DdsTimer] = []
        self._waitset = WaitSet(self.context.participant)
        #: what to run for each entity attached to the wait set, by its key (cyclone_raw.attach)
        self._handlers: dict[int, Callable[[], Any]] = {}
        #: attach key -> rank in the order the entities were attached (the handlers' order)
        self._made: dict[int, int] = {}
        self._attached = itertools.count()
        self._triggered = key_slots(0)
        sim_time = self.declare_parameter("use_sim_time", False, read_only=True).value
        self._clock = Clock(sim=bool(sim_time))
        self.context.nodes.append(self)
        if self._clock.sim:
            self.create_subscription("rosgraph_msgs/msg/Clock", "/clock", self._on_clock, CLOCK)
        self.context.publish_graph()

    # -- identity, logging, time, parameters -----------------------------------------------
    def get_name(self) -> str:
        """The node's name after ``__node`` remapping."""
        return self._name

    def get_namespace(self) -> str:
        """The node's namespace after ``__ns`` remapping."""
        return self._namespace

    def get_fully_qualified_name(self) -> str:
        """Namespace and name as one absolute name (``/frame/sim_node``)."""
        return self._namespace.rstrip("/") + "/" + self._name

    def get_logger(self) -> Logger:
        """The node's logger (its level from ``--ros-args --log-level``)."""
        return self._logger

    def get_clock(self) -> Clock:
        """The node's clock: system time, or sim time from ``/clock`` with ``use_sim_time``."""
        return self._clock

    def _on_clock(self, msg: Any) -> None:
        self._clock.set_sim_time(messages.stamp_ns(msg.clock))

    def declare_parameter(
        self, name: str, default: Any = None, read_only: bool = False, *,
        descriptor: params.ParameterDescriptor | None = None,
    ) -> params.Parameter:
        """Declare ``name`` in the node's parameter store (overrides from ``--ros-args`` applied)
        and return it with its value."""
        descriptor = params.described(descriptor, read_only=read_only)
        return params.Parameter(name, self._params.declare(name, default, descriptor))

    def get_parameter(self, name: str) -> params.Parameter:
        """The declared parameter ``name`` with its current value."""
        return params.Parameter(name, self._params.get(name))

    def add_on_set_parameters_callback(self, callback: params.SetCallback) -> None:
        """Ask ``callback`` before each set of the node's parameters (the parameter services
        included)."""
        self._params.callbacks.append(callback)

    # -- endpoints ---------------------------------------------------------------------------
    def resolve_topic_name(self, topic: str) -> str:
        """``topic`` as an absolute name in the node's namespace, then remapped by ``-r
        from:=to``."""
        full = names.resolve_topic(topic, self._namespace, self._name)
        return self._remaps.get(full, full)

    def create_publisher(
        self, msg_type: str | type, topic: str, qos: QoSProfile | str | int
    ) -> DdsPublisher:
        """A :class:`DdsPublisher` on the resolved ``topic``; the node list is published again with
        its writer."""
        topic = self.resolve_topic_name(topic)
        pub = DdsPublisher(self, messages.type_name(msg_type), topic, as_profile(qos))
        self._publishers.append(pub)
        self.context.publish_graph()
        return pub

    def create_subscription(
        self, msg_type: str | type, topic: str, callback: Callable[..., None],
        qos: QoSProfile | str | int, raw: bool = False,
    ) -> DdsSubscription:
        """A :class:`DdsSubscription` on the resolved ``topic``, its reader attached to the node's
        wait set; a raw one takes the process's own samples in-process when :mod:`.intra_process` is
        on."""
        topic = self.resolve_topic_name(topic)
        sub = DdsSubscription(
            self, messages.type_name(msg_type), topic, callback, as_profile(qos), raw,
            intra=raw and intra_process.enabled(),
        )
        self._subscriptions.append(sub)
        self.attach(sub.condition, sub.take_and_dispatch)
        self.context.publish_graph()
        return sub

    def destroy_publisher(self, pub: DdsPublisher) -> None:
        """Delete ``pub``'s writer and publish the node list without it."""
        self._publishers.remove(pub)
        pub.release()
        self.context.publish_graph()

    def create_polled_subscription(
        self, msg_type: str | type, topic: str, qos: QoSProfile | str | int,
    ) -> DdsSubscription:
        """A reader outside the node's wait set: nothing wakes for its samples."""
        topic = self.resolve_topic_name(topic)
        sub = DdsSubscription(self, messages.type_name(msg_type), topic, interface.never_called,
                              as_profile(qos), raw=True)
        self._polled.append(sub)
        self.context.publish_graph()
        return sub

    def destroy_subscription(self, sub: DdsSubscription) -> None:
        """Detach and delete ``sub``'s reader and publish the node list without it."""
        if sub in self._polled:
            self._polled.remove(sub)
        else:
            self.detach(sub.condition)
            self._subscriptions.remove(sub)
        sub.release()
        self.context.publish_graph()

    def create_timer(
        self, period_s: float, callback: Callable[[], None], clock: Clock | None = None
    ) -> DdsTimer:
        """A :class:`DdsTimer` on ``clock`` (default the node's), run by :meth:`spin_once`."""
        timer = DdsTimer(period_s, callback, clock or self._clock)
        self._timers.append(timer)
        return timer

    def reader_gids(self) -> list[bytes]:
        """The GUIDs of the node's readers, as the node list publishes them."""
        return [sub.gid for sub in (*self._subscriptions, *self._polled)]

    def writer_gids(self) -> list[bytes]:
        """The GUIDs of the node's writers, as the node list publishes them."""
        return [pub.gid for pub in self._publishers]

    # -- graph -------------------------------------------------------------------------------
    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every ROS topic with a publisher or subscription on the network, sorted."""
        found: dict[str, set[str]] = {}
        for kind in ("publication", "subscription"):
            for ep in self.context.endpoints(kind):
                found.setdefault(ep.topic_name, set()).add(ep.topic_type)
        return [(topic, sorted(types)) for topic, types in sorted(found.items())]

    def get_publishers_info_by_topic(self, topic: str) -> list[interface.TopicEndpointInfo]:
        """Every alive publisher of ``topic`` (resolved in the node's namespace) in the graph."""
        full = names.resolve_topic(topic, self._namespace, self._name)
        return [ep for ep in self.context.endpoints("publication") if ep.topic_name == full]

    def count_publishers(self, topic: str) -> int:
        """How many alive publishers of ``topic`` the graph holds."""
        return len(self.get_publishers_info_by_topic(topic))

    def get_subscriptions_info_by_topic(self, topic: str) -> list[interface.TopicEndpointInfo]:
        """Every alive subscription of ``topic`` (resolved in the node's namespace) in the graph."""
        full = names.resolve_topic(topic, self._namespace, self._name)
        return [ep for ep in self.context.endpoints("subscription") if ep.topic_name == full]

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        """``(name, namespace)`` of every node that alive participants publish, sorted."""
        return sorted(
            (name, namespace)
            for nodes in self.context.node_names().values()
            for namespace, name, _ in nodes
        )

    def get_service_names_and_types_by_node(
        self, node_name: str, node_namespace: str, server: bool = True
    ) -> list[tuple[str, list[str]]]:
        """A node's service servers (``server``) or clients, from their request endpoints."""
        found: dict[str, set[str]] = {}
        for namespace, name, service, rtype in self.context.services(
                "subscription" if server else "publication"):
            if (name, namespace) == (node_name, node_namespace):
                found.setdefault(service, set()).add(rtype)
        return [(service, sorted(types)) for service, types in sorted(found.items())]

    # -- execution ---------------------------------------------------------------------------
    def attach(self, condition: Any, handler: Callable[[], Any]) -> None:
        """Run ``handler`` when ``condition`` triggers the node's wait set."""
        key = attach(self._waitset, condition)
        self._handlers[key] = handler
        self._made[key] = next(self._attached)
        self._triggered = key_slots(len(self._handlers))

    def detach(self, condition: Any) -> None:
        """Stop running the handler of ``condition`` and take it out of the wait set."""
        key = attach_key(self._waitset, condition)
        del self._handlers[key], self._made[key]
        self._waitset.detach(condition)

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Wait for data or the next timer (at most ``timeout_sec``), then run callbacks."""
        if not interface.ok():
            return
        interface.freeze_setup_objects()
        wait_ns = MAX_WAIT_NS if timeout_sec is None else min(MAX_WAIT_NS, int(timeout_sec * 1e9))
        for timer in self._timers:
            due = timer.time_until_call_ns()
            if due is not None:
                wait_ns = min(wait_ns, max(due, 0))
        keys = self._triggered
        count = wait_triggered(self._waitset, wait_ns, keys)
        # in the order the entities were made (the wait set's order is its own): a
        # callback that answers a sample must not run before the other topics of that sample
        # are taken, or the answer's reply can overwrite one of them (a depth-1 /clock reader)
        triggered = keys[:count] if count < 2 else sorted(keys[:count], key=self._made.__getitem__)
        for key in triggered:
            handler = self._handlers.get(key)   # None: detached by an earlier callback
            if handler is not None:
                handler()
        for timer in list(self._timers):
            timer.call_if_due()

    def destroy_node(self) -> None:
        """Release every entity of the node and drop it from the node list."""
        if self not in self.context.nodes:
            return
        interface.node_destroyed(self)
        delete(self._waitset)
        for entity in (*self._publishers, *self._subscriptions, *self._polled):
            entity.release()
        self._publishers.clear()
        self._subscriptions.clear()
        self._polled.clear()
        self._timers.clear()
        self.context.remove_node(self)

