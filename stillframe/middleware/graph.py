"""The ROS graph as data, for the command-line tools: a snapshot of nodes, topics, endpoints and
services taken from a node (:func:`snapshot`), waiting until discovery settles
(:func:`settle`), sent as JSON by the graph daemon, and names close to a misspelt one
(:func:`suggest`).

This module imports no middleware and no message types (a warm ``stillframe topic list`` reads
a snapshot from the daemon without loading DDS, rclpy or the typestore); the node it is handed
is any :class:`stillframe.middleware.interface.Node`.
"""

from __future__ import annotations

import difflib
import time
from dataclasses import asdict, dataclass, field
from typing import Any

from stillframe.middleware import names
from stillframe.middleware.qos import (
    INFINITE_NS,
    Durability,
    History,
    Liveliness,
    QoSProfile,
    Reliability,
)

#: discovery has settled when the graph did not change for this long [s], and at least
#: :data:`ANNOUNCE_S` has passed. A new participant's view of a running graph grows in steps
#: about a second apart, on either backend, until every participant has announced itself; Fast
#: DDS participants announce themselves every 3 s (``leaseDuration_announcementperiod``), so
#: after :data:`ANNOUNCE_S` each has done so at least once
QUIET_S = 1.0
ANNOUNCE_S = 3.2
#: and is given up on (the answer then says what was seen) after this long [s]
SETTLE_LIMIT_S = 5.0
SETTLE_POLL_S = 0.05
#: DDS vendor ids (the first two bytes of an endpoint's GUID), as the OMG assigns them
VENDORS = {b"\x01\x0f": "Fast DDS", b"\x01\x10": "Cyclone DDS"}


@dataclass(frozen=True)
class TopicEndpointInfo:
    """One publisher or subscription of a topic, as discovered (like rclpy's); the backends
    return these (:mod:`stillframe.middleware.interface` re-exports it)."""

    topic_name: str
    topic_type: str
    topic_type_hash: str
    endpoint_gid: bytes
    qos_profile: QoSProfile
    node_name: str = ""
    node_namespace: str = ""


@dataclass(frozen=True)
class Endpoint(TopicEndpointInfo):
    """An endpoint in a graph snapshot: the info and whether it publishes or subscribes."""

    kind: str = "PUBLISHER"   # or "SUBSCRIPTION", rmw's endpoint type names

    @property
    def node(self) -> str:
        """The fully qualified name of the endpoint's node ('' if not known)."""
        return fqn(self.node_namespace, self.node_name) if self.node_name else ""

    @property
    def vendor(self) -> str:
        """The DDS vendor of the endpoint, from the first two bytes of its GID ('' if unknown)."""
        return VENDORS.get(bytes(self.endpoint_gid[:2]), "")

    def describe(self) -> str:
        """The block ``ros2 topic info -v`` prints (rclpy's ``TopicEndpointInfo.__str__``)."""
        qos = self.qos_profile
        history = (qos.history.name if qos.history != History.KEEP_LAST
                   else f"{qos.history.name} ({qos.depth})")
        return "\n".join([
            f"Node name: {self.node_name}",
            f"Node namespace: {self.node_namespace}",
            f"Topic type: {self.topic_type}",
            f"Topic type hash: {self.topic_type_hash}",
            f"Endpoint type: {self.kind}",
            f"GID: {'.'.join(format(b, '02x') for b in self.endpoint_gid)}",
            "QoS profile:",
            f"  Reliability: {qos.reliability.name}",
            f"  History (Depth): {history}",
            f"  Durability: {qos.durability.name}",
            f"  Lifespan: {duration_text(qos.lifespan_ns)}",
            f"  Deadline: {duration_text(qos.deadline_ns)}",
            f"  Liveliness: {qos.liveliness.name}",
            f"  Liveliness lease duration: {duration_text(qos.liveliness_lease_duration_ns)}",
        ])


def duration_text(ns: int) -> str:
    """rclpy's ``str(Duration)``: ``Infinite`` or ``N nanoseconds``."""
    return "Infinite" if ns >= INFINITE_NS else f"{ns} nanoseconds"


def fqn(namespace: str, name: str) -> str:
    """The fully qualified name of ``name`` in ``namespace`` (``/frame`` and ``sim_node``:
    ``/frame/sim_node``)."""
    return namespace.rstrip("/") + "/" + name


@dataclass(frozen=True)
class Service:
    """A service server or client of a node."""

    node: str                 # fully qualified node name
    name: str
    types: tuple[str, ...]
    server: bool


@dataclass
class Graph:
    """What a node saw of the graph, with the graph queries of rclpy's node."""

    nodes: list[tuple[str, str]] = field(default_factory=list)
    topics: list[tuple[str, list[str]]] = field(default_factory=list)
    endpoints: list[Endpoint] = field(default_factory=list)
    services: list[Service] = field(default_factory=list)
    #: seconds discovery took to settle, and whether it did within the limit
    settle_s: float = 0.0
    settled: bool = True

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        """``(name, namespace)`` of every node seen."""
        return list(self.nodes)

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every topic seen with its type names."""
        return list(self.topics)

    def get_publishers_info_by_topic(self, topic: str) -> list[Endpoint]:
        """The publishers of ``topic`` (a fully qualified name)."""
        return [e for e in self.endpoints if e.topic_name == topic and e.kind == "PUBLISHER"]

    def get_subscriptions_info_by_topic(self, topic: str) -> list[Endpoint]:
        """The subscriptions of ``topic`` (a fully qualified name)."""
        return [e for e in self.endpoints if e.topic_name == topic and e.kind == "SUBSCRIPTION"]

    def node_names(self, include_hidden: bool = False) -> list[str]:
        """Fully qualified node names, sorted (hidden ones, a name starting with '_', left out
        unless asked for, as ``ros2 node list`` does)."""
        return sorted(fqn(ns, name) for name, ns in self.nodes
                      if include_hidden or not name.startswith("_"))

    def topic_names(self, include_hidden: bool = False) -> list[str]:
        """The topic names, hidden ones (:func:`.names.is_hidden`) left out unless asked for."""
        return [t for t, _ in self.topics if include_hidden or not names.is_hidden(t)]

    def to_json(self) -> dict[str, Any]:
        """The graph as plain JSON values (GIDs in hex, QoS by name), what the graph daemon
        sends."""
        return {
            "nodes": self.nodes, "topics": self.topics,
            "endpoints": [dict(asdict(e), endpoint_gid=e.endpoint_gid.hex(),
                               qos_profile=_qos_json(e.qos_profile)) for e in self.endpoints],
            "services": [asdict(s) for s in self.services],
            "settle_s": self.settle_s, "settled": self.settled,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Graph:
        """The graph from :meth:`to_json`'s document."""
        return cls(
            nodes=[tuple(n) for n in data["nodes"]],
            topics=[(t, list(types)) for t, types in data["topics"]],
            endpoints=[Endpoint(**dict(e, endpoint_gid=bytes.fromhex(e["endpoint_gid"]),
                                       qos_profile=_qos_from_json(e["qos_profile"])))
                       for e in data["endpoints"]],
            services=[Service(**dict(s, types=tuple(s["types"]))) for s in data["services"]],
            settle_s=data["settle_s"], settled=data["settled"],
        )


_QOS_ENUMS = {"history": History, "reliability": Reliability, "durability": Durability,
              "liveliness": Liveliness}


def _qos_json(qos: QoSProfile) -> dict[str, Any]:
    return {k: (v.name if k in _QOS_ENUMS else v) for k, v in asdict(qos).items()}


def _qos_from_json(data: dict[str, Any]) -> QoSProfile:
    return QoSProfile(**{k: (_QOS_ENUMS[k][v] if k in _QOS_ENUMS else v)
                         for k, v in data.items()})


def snapshot(node: Any) -> Graph:
    """The graph as ``node`` sees it now."""
    topics = node.get_topic_names_and_types()
    endpoints = []
    for topic, _ in topics:
        for kind, infos in (("PUBLISHER", node.get_publishers_info_by_topic(topic)),
                            ("SUBSCRIPTION", node.get_subscriptions_info_by_topic(topic))):
            endpoints += [Endpoint(topic, i.topic_type, i.topic_type_hash, bytes(i.endpoint_gid),
                                   i.qos_profile, i.node_name, i.node_namespace, kind=kind)
                          for i in infos]
    nodes = node.get_node_names_and_namespaces()
    services = [
        Service(fqn(ns, name), service, tuple(types), server)
        for name, ns in nodes
        for server in (True, False)
        for service, types in node.get_service_names_and_types_by_node(name, ns, server=server)
    ]
    return Graph(nodes=nodes, topics=topics, endpoints=endpoints, services=services)


#: the node name rmw gives an endpoint whose participant's node list has not arrived yet
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"
#: names an endpoint's node has before its node is known: ours, and rmw's graph cache
UNNAMED_NODES = ("", UNKNOWN_NODE)


def _signature(node: Any) -> tuple:
    """What changes while discovery goes on: nodes, topics, their endpoints and the endpoints
    whose node is not known yet (counted as a change until it is)."""
    topics = node.get_topic_names_and_types()
    endpoints = [(node.get_publishers_info_by_topic(t), node.get_subscriptions_info_by_topic(t))
                 for t, _ in topics]
    unknown = sum(e.node_name in UNNAMED_NODES for pubs, subs in endpoints
                  for e in (*pubs, *subs))
    return (tuple(node.get_node_names_and_namespaces()),
            tuple((t, tuple(types)) for t, types in topics),
            tuple((len(pubs), len(subs)) for pubs, subs in endpoints), unknown)


def settle(node: Any, *, quiet_s: float = QUIET_S, min_s: float = ANNOUNCE_S,
           limit_s: float = SETTLE_LIMIT_S, now: Any = time.monotonic) -> tuple[float, bool]:
    """Spin ``node`` until its view of the graph has not changed for ``quiet_s`` and every
    endpoint's node is known (discovery has settled), not before ``min_s`` and at most
    ``limit_s``. Returns the seconds it took and whether it settled. ``now`` is the clock (a
    test passes its own)."""
    start = now()
    last, since = _signature(node), start
    while (t := now()) - start < limit_s:
        if t - since >= quiet_s and t - start >= min(min_s, limit_s) and not last[-1]:
            return t - start, True
        node.spin_once(SETTLE_POLL_S)
        current = _signature(node)
        if current != last:
            last, since = current, now()
    return now() - start, False


def suggest(name: str, candidates: list[str], n: int = 3) -> list[str]:
    """The names of ``candidates`` closest to a misspelt ``name`` (difflib's ratio >= 0.6)."""
    return difflib.get_close_matches(name, candidates, n=n)


def did_you_mean(name: str, candidates: list[str]) -> str:
    """`` (did you mean /a, /b?)`` for the names close to ``name``, '' if none."""
    close = suggest(name, candidates)
    return f" (did you mean {', '.join(close)}?)" if close else ""
