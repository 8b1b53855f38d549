"""Writer identity on the loop's input topics (issue 11): which writer a node takes samples from.

One :class:`WriterGate` per input topic. Samples are taken only from the writers of *one* node,
each identified by its writer GID (the DDS publication GUID the middleware hands with each
sample, ``MessageInfo.publisher_gid``): the node of the first writer seen, or, when ``pinned``
names a node, the node of that name in the ROS graph. A writer of another node is a second
writer: it is reported (:meth:`WriterGate.report`) and its samples are ignored, counted by
reason. A new writer of the same node (a restarted simulator, estimator or controller: a new
GUID under the old name) is taken; so is, when the node is not pinned, a writer that the graph
cannot name yet once every writer taken so far has left the graph (a restart before its name
arrived).

The hot path is a set lookup: a GID already taken or already refused is decided without the
graph, and so is an unpinned gate's first writer (reading the graph costs about 9 ms in a running
loop, which the first sample then paid in each node). The graph is asked only for a later GID not
seen before, and at most every
:data:`RECHECK_NS` for one it could not name yet (``unknown_writer``) or, where the middleware
gives no GID (real rclpy Jazzy: its message info has none), for how many writers the topic has:
while the graph shows more than one, every sample is refused (``ambiguous_writer``), since the
gate cannot tell them apart.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from stillframe.middleware import api

#: why a sample is refused for its writer
REASONS = ("second_writer", "unknown_writer", "ambiguous_writer")

#: how often [ns] the graph is asked again about a writer it could not name, or, without writer
#: GIDs, how many writers a topic has
RECHECK_NS = 50_000_000

#: (writer GID, node namespace/name) of a topic's current writers, from the ROS graph
GraphWriters = Callable[[], list[tuple[bytes, str]]]


def graph_writers(node: api.Node, topic: str) -> GraphWriters:
    """The writers of ``topic`` in ``node``'s view of the graph, as (GID, ``/namespace/name``)
    (the name ``/`` while the graph has not named the writer's node)."""
    def writers() -> list[tuple[bytes, str]]:
        return [(ep.endpoint_gid, f"{ep.node_namespace.rstrip('/')}/{ep.node_name}")
                for ep in node.get_publishers_info_by_topic(topic)]

    return writers


def same_node(name: str, wanted: str) -> bool:
    """Whether the graph's ``/namespace/name`` is the node ``wanted`` (``name`` or the full
    name)."""
    return name == wanted or name.rsplit("/", 1)[-1] == wanted


@dataclass
class WriterGate:
    """The writer decision for one topic.

    ``pinned``: the node (``name`` or ``/namespace/name``) whose writers are taken, empty for
    the first writer seen; ``writers``: the topic's writers in the graph; ``clock``: monotonic
    nanoseconds (for :data:`RECHECK_NS`).
    """

    pinned: str
    writers: GraphWriters
    clock: Callable[[], int] = time.monotonic_ns
    #: how many writers the topic has in the graph (None: ``len(writers())``), asked every
    #: :data:`RECHECK_NS` inside the loop for samples without a GID, so it must be cheap
    count_writers: Callable[[], int] | None = None
    owner: str = ""                 # the node taken, ``/namespace/name`` ("" while not known)
    taken: set[bytes] = field(default_factory=set)
    intruders: set[bytes] = field(default_factory=set)
    unresolved: dict[bytes, int] = field(default_factory=dict)   # GID -> when last asked
    rejected: Counter = field(default_factory=Counter)
    blind_writers: int = 0          # writers in the graph, for samples without a GID
    blind_until: int = -1

    def admits(self, gid: bytes) -> bool:
        """Whether a sample from writer ``gid`` is taken; counts the reason if not."""
        if gid in self.taken:
            return True
        reason = "second_writer" if gid in self.intruders else self._decide(gid)
        if reason is None:
            return True
        self.rejected[reason] += 1
        return False

    def _decide(self, gid: bytes) -> str | None:
        now = self.clock()
        if not gid:
            if now >= self.blind_until:
                count = self.count_writers() if self.count_writers else len(self.writers())
                self.blind_writers, self.blind_until = count, now + RECHECK_NS
            return "ambiguous_writer" if self.blind_writers > 1 else None
        if not self.taken and not self.pinned:
            self.taken.add(gid)             # the first writer seen: no need to ask the graph
            return None
        if now < self.unresolved.get(gid, now - RECHECK_NS) + RECHECK_NS:
            return "unknown_writer"         # asked the graph a moment ago
        listed = self.writers()
        graph = {g: name for g, name in listed if name.strip("/")}
        name = graph.get(gid)
        wanted = self.pinned or self.owner or next(
            (graph[g] for g in self.taken if g in graph), "")
        if name is not None and wanted:
            if not same_node(name, wanted):
                self.intruders.add(gid)
                self.unresolved.pop(gid, None)
                return "second_writer"
        elif self.pinned or self.taken & {g for g, _ in listed}:
            self.unresolved[gid] = now      # cannot tell yet: ask again later
            return "unknown_writer"
        else:
            self.taken.clear()              # the node taken is gone: a restart, not named yet
        self.taken.add(gid)
        self.owner = name or self.owner
        self.unresolved.pop(gid, None)
        return None

    def has_seen_samples(self) -> bool:
        """Whether samples came: from a writer taken, or without a GID (its writers counted)."""
        return bool(self.taken) or self.blind_until >= 0

    def name_of(self, gid: bytes) -> str:
        """The node of writer ``gid`` in the graph, its GID in hex while the graph has none."""
        return next((name for g, name in self.writers() if g == gid and name.strip("/")),
                    gid.hex())

    def ignored(self) -> list[str]:
        """The other writers seen (refused, or not named yet), by node name or GID."""
        return sorted({self.name_of(gid) for gid in (*self.intruders, *self.unresolved)})

    def report(self) -> dict[str, object]:
        """For ``/diagnostics``: the node taken, the writers ignored, refusals by reason."""
        if not self.owner and self.taken:   # the first writer was taken without its name
            self.owner = next((name for g, name in self.writers()
                               if g in self.taken and name.strip("/")), "")
        taken = self.owner or ", ".join(sorted(self.name_of(g) for g in self.taken))
        return {"writer": taken, "ignored_writers": ",".join(self.ignored()),
                **{f"rejected_{r}": self.rejected[r] for r in REASONS}}


class InputGates:
    """The :class:`WriterGate` of each input topic of a node, reported together; ``pins`` maps
    the node's parameters that name the node a gate takes to their values ("": the first writer
    seen; declared by the node runtime, :mod:`stillframe.node_runtime.declarations`)."""

    def __init__(self, node: api.Node, pins: dict[str, str]) -> None:
        self.node = node
        self.gates: dict[str, WriterGate] = {}
        self.pins = dict(pins)
        self.samples_seen = False       # a gate has seen samples (:meth:`keep_graph_read`)
        self.next_graph_read = 0

    def add(self, topic: str, parameter: str) -> WriterGate:
        """The gate of ``topic``, taking the writers of the node ``parameter`` names."""
        gate = WriterGate(self.pins[parameter], graph_writers(self.node, topic),
                          count_writers=lambda: self.node.count_publishers(topic))
        self.gates[topic] = gate
        return gate

    def read_graph(self) -> None:
        """Read the graph for every gate's topic (the middleware reads only what changed since
        its last read; its first read of a running loop's 55 endpoints takes milliseconds)."""
        for gate in self.gates.values():
            gate.writers()

    def keep_graph_read(self) -> None:
        """Until a first sample comes, read the graph every :data:`RECHECK_NS`: a node
        calls this in its loop, so that the graph is read while it waits for the simulator,
        not in the first report or decision that needs it, inside the loop."""
        if self.samples_seen:
            return
        if any(gate.has_seen_samples() for gate in self.gates.values()):
            self.samples_seen = True
        elif (now := time.monotonic_ns()) >= self.next_graph_read:
            self.read_graph()
            self.next_graph_read = now + RECHECK_NS

    def values(self) -> dict[str, object]:
        """Every gate's report, keys prefixed by the topic (``/`` as ``_``)."""
        return {f"{topic.strip('/').replace('/', '_')}_{key}": value
                for topic, gate in self.gates.items() for key, value in gate.report().items()}

    def refused(self) -> int:
        """Samples refused for their writer, on every topic."""
        return sum(sum(gate.rejected.values()) for gate in self.gates.values())

    def message(self) -> str:
        """Which second writers are being ignored, for the status message."""
        return "; ".join(f"second writer on {topic} ignored: {', '.join(names)}"
                         for topic, gate in self.gates.items() if (names := gate.ignored()))
