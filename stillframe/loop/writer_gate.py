"""Writer identity on the loop's input topics: which writer a node takes samples from.

One :class:`WriterGate` per input topic. With the run's token (``run_token``, docs/nodes.md
"Writer identity"), a sample is the loop's own when its ``header.frame_id`` ends with the token
(:func:`stillframe.contract.codecs.carries_token`: a length read and a slice compared, before the
sample is decoded), whatever its writer, its order of arrival or its node's name; every other
sample is a foreign writer's, refused and counted (``foreign_writer``), and the writer named from
the graph: by its GID where the middleware hands one, else as the topic's writers other than the
loop's own node (by its fully qualified name; by its writer's GID in hex while the graph has no
name for its node, which a launch replaces by the name its own graph has at the end of the run).
``/clock`` carries no header, so no token: its gate (the controller's, with ``use_sim_time``)
decides as below.

Without a token (nodes started by hand without one), samples are taken only from the writers of
*one* node, each identified by its writer GID (the DDS publication GUID the middleware hands
with each sample, ``MessageInfo.publisher_gid``): the node of the first writer seen, or, when
``pinned`` names a node, the node of that name in the ROS graph (a relative name resolved in the
gate's namespace, as ROS resolves it: ``controller_node`` is ``/frame/controller_node``, never
``/controller_node``). A writer of another node is a second writer: it is reported
(:meth:`WriterGate.report`) and its samples are ignored, counted by reason. A new writer of the
same node (a restarted simulator, estimator or controller: a new GUID under the old name) is
taken; so is, when the node is not pinned, a writer that the graph cannot name yet once every
writer taken so far has left the graph (a restart before its name arrived).

The hot path is a set lookup: a GID already taken or already refused is decided without the
graph, and so is an unpinned gate's first writer (a read of the graph in a running loop costs
milliseconds, more than a sample period at 1 kHz, which the first sample would pay in each
node). The graph is asked only for a later GID not seen before, and at most every :data:`RECHECK_NS`
for one it could not name yet (``unknown_writer``).

Without GIDs (real rclpy Jazzy: its message info has none) the gate decides from what arrives,
not from how many publishers the graph shows: a publisher that exists but never writes (``ros2
topic pub`` before its first message, a Foxglove publish panel, a teleop tool) changes nothing.
Each DDS writer numbers its samples 1, 2, 3 …, and rclpy hands that publication sequence number
with each sample, so the samples fall into *streams* (:class:`SequenceStreams`): a sample
continues the stream whose last number is the nearest below its own (at most :data:`MAX_GAP`
below), or starts a new one. The first stream is taken; a later stream is another writer's and is
refused (``second_writer``), unless the graph shows that only the taken node writes the topic, or
shows a new writer of that node (a restart). Its node is named from the graph: the topic's
writers that are not the taken node's. Two writers whose numbers run side by side cannot be told
apart: a sample as near to two streams is refused (``ambiguous_writer``). Only where a backend
gives neither GID nor sequence number is the count of writers asked for, every
:data:`RECHECK_NS`, and every sample refused while it is above one. Order of arrival decides
here, which is why a launch gives its nodes a token.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from stillframe.contract.codecs import carries_token, token_suffix
from stillframe.contract.topics import DEFAULT_NAMESPACE
from stillframe.middleware import api
from stillframe.middleware.graph import UNNAMED_NODES, fqn

#: why a sample is refused for its writer: without the run's token, or (without a token) another
#: node's, a node the graph does not name yet, as near to two writers' numbers
REASONS = ("foreign_writer", "second_writer", "unknown_writer", "ambiguous_writer")

#: how often [ns] the graph is asked again about a writer it could not name, or, without writer
#: GIDs, how many writers a topic has
RECHECK_NS = 50_000_000

#: how far [samples] a writer's sequence number may jump over samples lost or not read, and still
#: continue its stream; a larger jump starts a new stream
MAX_GAP = 256

#: wall time [ns] after which a stream not taken that wrote nothing is forgotten
STREAM_IDLE_NS = 1_000_000_000

#: the first byte of a stream's key, which stands in for a GID (real GIDs are 16 bytes of a GUID)
STREAM_KEY = b"#"

#: (writer GID, node namespace/name) of a topic's current writers, from the ROS graph
GraphWriters = Callable[[], list[tuple[bytes, str]]]


def graph_writers(node: api.Node, topic: str) -> GraphWriters:
    """The writers of ``topic`` in ``node``'s view of the graph, as (GID, ``/namespace/name``)
    (the name ``/`` while the graph has not named the writer's node: rmw's graph cache calls
    it ``_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_`` until the participant's node list comes)."""
    def writers() -> list[tuple[bytes, str]]:
        return [(ep.endpoint_gid, "/" if ep.node_name in UNNAMED_NODES
                 else fqn(ep.node_namespace, ep.node_name))
                for ep in node.get_publishers_info_by_topic(topic)]

    return writers


@dataclass
class SequenceStreams:
    """Samples without a writer GID told apart by their writers' publication sequence numbers
    (module docstring): :meth:`key` gives the stream a sample continues, as a stand-in GID."""

    clock: Callable[[], int]
    heads: dict[bytes, int] = field(default_factory=dict)       # key -> last number
    last_seen: dict[bytes, int] = field(default_factory=dict)   # key -> when
    count: int = 0

    def key(self, sequence: int, keep: set[bytes]) -> bytes | None:
        """The stream sample ``sequence`` continues (a new one if none), or None when two
        streams are as near (the sample is ambiguous); streams idle for :data:`STREAM_IDLE_NS`
        are forgotten, except those in ``keep``."""
        now = self.clock()
        for old in [k for k, t in self.last_seen.items()
                    if now - t > STREAM_IDLE_NS and k not in keep]:
            del self.heads[old], self.last_seen[old]
        below = [(head, k) for k, head in self.heads.items() if 0 < sequence - head <= MAX_GAP]
        if below:
            nearest = max(head for head, _ in below)
            keys = [k for head, k in below if head == nearest]
            if len(keys) > 1:
                return None
            key = keys[0]
        else:
            self.count += 1
            key = STREAM_KEY + str(self.count).encode()
        self.heads[key], self.last_seen[key] = sequence, now
        return key


def resolve_node(name: str, namespace: str) -> str:
    """A node name as ROS resolves it: a relative one in ``namespace`` (``controller_node`` in
    ``/frame`` is ``/frame/controller_node``), a fully qualified one as it is."""
    return name if name.startswith("/") else fqn(namespace, name)


def same_node(name: str, wanted: str, namespace: str) -> bool:
    """Whether the graph's ``/namespace/name`` is the node ``wanted`` resolved in ``namespace``
    (:func:`resolve_node`): never a node of the same name in another namespace."""
    return name == resolve_node(wanted, namespace)


@dataclass
class WriterGate:
    """The writer decision for one topic.

    ``pinned``: the node (``name`` in ``namespace``, or ``/namespace/name``) whose writers are
    taken, empty for the first writer seen; ``writers``: the topic's writers in the graph;
    ``clock``: monotonic nanoseconds (for :data:`RECHECK_NS`); ``token``: the suffix every
    ``frame_id`` of the run ends with (:func:`~stillframe.contract.codecs.token_suffix`; empty:
    no token); ``own``: the node expected to write the topic (the pin, else the loop's node of
    that input), by which the foreign writers are told apart in the graph without GIDs.
    """

    pinned: str
    writers: GraphWriters
    clock: Callable[[], int] = time.monotonic_ns
    namespace: str = DEFAULT_NAMESPACE
    token: bytes = b""
    own: str = ""
    #: how many writers the topic has in the graph (None: ``len(writers())``), asked every
    #: :data:`RECHECK_NS` inside the loop for samples without a GID, so it must be cheap
    count_writers: Callable[[], int] | None = None
    owner: str = ""                 # the node taken, ``/namespace/name`` ("" while not known)
    taken: set[bytes] = field(default_factory=set)
    intruders: set[bytes] = field(default_factory=set)
    unresolved: dict[bytes, int] = field(default_factory=dict)   # GID -> when last asked
    rejected: Counter = field(default_factory=Counter)
    blind_writers: int = 0          # writers in the graph, for samples without GID or number
    blind_until: int = -1
    streams: SequenceStreams | None = None      # samples without a GID, by sequence number
    owner_gids: set[bytes] = field(default_factory=set)     # the taken node's, for streams
    #: a refused stream -> when to ask the graph again (a restart it shows late)
    stream_recheck: dict[bytes, int] = field(default_factory=dict)
    #: refusals not yet announced (:meth:`InputGates.announce`)
    news: bool = False
    #: with a token: the GIDs of the writers whose samples lacked it, and whether a sample of
    #: the run came
    foreign: set[bytes] = field(default_factory=set)
    seen: bool = False
    #: GIDs the graph named as the loop's own (or the taken) node's writers
    own_gids: set[bytes] = field(default_factory=set)

    def __post_init__(self) -> None:
        self.pinned = resolve_node(self.pinned, self.namespace) if self.pinned else ""
        self.own = resolve_node(self.own, self.namespace) if self.own else self.pinned

    def admits(self, gid: bytes, sequence: int = 0, data: bytes | memoryview = b"") -> bool:
        """Whether a sample from writer ``gid`` (or, without one, numbered ``sequence`` by its
        writer) is taken; with a token, whether its CDR ``data`` carries it; counts the reason
        if not."""
        if self.token:
            if carries_token(data, self.token):
                self.seen = True
                return True
            if gid:
                self.foreign.add(gid)
            return self._refuse("foreign_writer")
        if not gid and sequence:
            if self.streams is None:
                self.streams = SequenceStreams(self.clock)
            gid = self.streams.key(sequence, self.taken)
            if gid is None:
                return self._refuse("ambiguous_writer")
        if gid in self.taken:
            return True
        refused = gid in self.intruders and not (
            gid.startswith(STREAM_KEY) and self.clock() >= self.stream_recheck[gid])
        reason = "second_writer" if refused else self._decide(gid)
        return True if reason is None else self._refuse(reason)

    def _refuse(self, reason: str) -> bool:
        self.rejected[reason] += 1
        self.news = True
        return False

    def _decide(self, gid: bytes) -> str | None:
        now = self.clock()
        if gid.startswith(STREAM_KEY):
            return self._decide_stream(gid)
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
            if name != wanted:
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

    def _decide_stream(self, key: bytes) -> str | None:
        """A stream not taken yet: the first one, a restart of the taken node (a new writer of it
        in the graph), or, while the graph shows only the taken node's writers, a stream of that
        node (its numbers jumped); any other is another writer, asked about again after
        :data:`RECHECK_NS` (the graph may show a restart after its first samples)."""
        listed = self.writers()
        wanted = self.pinned or self.owner
        if not wanted and not self.taken:   # the one node writing the topic, if one
            nodes = {name for _, name in listed if name.strip("/")}
            wanted = next(iter(nodes)) if len(nodes) == 1 else ""
        own = {g for g, name in listed if wanted and name == wanted}
        self.owner_gids = self.owner_gids or own     # taken before the graph named its node
        alone = bool(wanted) and all(g in own for g, _ in listed)
        if self.taken and not alone and not own - self.owner_gids:
            self.intruders.add(key)
            self.stream_recheck[key] = self.clock() + RECHECK_NS
            return "second_writer"
        self.intruders.discard(key)
        self.taken = {key}
        self.owner = wanted
        self.owner_gids = own
        return None

    def suspects(self) -> list[str]:
        """Without GIDs: the writers of the topic other than the taken node's (with a token:
        than the loop's own node's), by their node's name, or by their GID in hex while the
        graph has no name for their node (as :meth:`name_of` gives a GID: a launch names those
        from its own graph at the end of the run). A writer the graph named as that node once is
        never a suspect."""
        wanted = self.own if self.token else self.pinned or self.owner
        listed = self.writers()
        if wanted:
            self.own_gids.update(g for g, name in listed if name == wanted)
        return sorted({name if name.strip("/") else g.hex() for g, name in listed
                       if not (wanted and name == wanted)
                       and (name.strip("/") or (g and g not in self.own_gids))})

    def has_seen_samples(self) -> bool:
        """Whether samples came: of the run, from a writer taken, or without a GID (its writers
        counted)."""
        return self.seen or bool(self.taken) or self.blind_until >= 0

    def foreign_names(self) -> list[str]:
        """With a token: the writers whose samples lacked it, by their GIDs' nodes where the
        middleware gave GIDs, else the topic's writers other than the loop's own node (``a or
        b`` when more than one: an idle publisher cannot be told from a writing one), or a second
        writer under the loop's own name."""
        if self.foreign:
            return sorted({self.name_of(gid) for gid in self.foreign})
        if others := self.suspects():
            return [" or ".join(others)]
        doubles = sum(name == self.own for _, name in self.writers())
        return [f"another writer named {self.own}" if doubles > 1 else "unnamed"]

    def name_of(self, gid: bytes) -> str:
        """The node of writer ``gid`` in the graph, its GID in hex while the graph has none; a
        stream's (no GID): the topic's other writers (:meth:`suspects`), or ``unnamed`` while
        the graph shows none."""
        if gid.startswith(STREAM_KEY):
            return " or ".join(self.suspects()) or "unnamed"
        return next((name for g, name in self.writers() if g == gid and name.strip("/")),
                    gid.hex())

    def ignored(self) -> list[str]:
        """The other writers seen (refused, or not named yet), by node name or GID."""
        if self.token:
            return self.foreign_names() if self.rejected["foreign_writer"] else []
        ambiguous = " or ".join(self.suspects()) if self.rejected["ambiguous_writer"] else ""
        return sorted({self.name_of(gid) for gid in (*self.intruders, *self.unresolved)}
                      | ({ambiguous or "unnamed"} if self.rejected["ambiguous_writer"] else set()))

    def report(self) -> dict[str, object]:
        """For ``/diagnostics``: the node taken, the writers ignored, refusals by reason."""
        if not self.owner and self.taken:   # the first writer was taken without its name
            listed = [(g, name) for g, name in self.writers() if name.strip("/")]
            self.owner = next((name for g, name in listed if g in self.taken or (
                self.pinned and name == self.pinned)), "")
        if self.token:
            taken = self.own
        elif self.owner or not self.taken:
            taken = self.owner
        elif self.pinned and any(g.startswith(STREAM_KEY) for g in self.taken):
            taken = self.pinned                 # no GID: the pin, until the graph names it
        elif any(g.startswith(STREAM_KEY) for g in self.taken):     # no GID, no pin, no name
            taken = " or ".join(sorted({name for _, name in self.writers() if name.strip("/")}))
        else:
            taken = ", ".join(sorted(self.name_of(g) for g in self.taken))
        return {"writer": taken, "ignored_writers": ",".join(self.ignored()),
                **{f"rejected_{r}": self.rejected[r] for r in REASONS}}


class InputGates:
    """The :class:`WriterGate` of each input topic of a node, reported together; ``pins`` maps
    the node's parameters that name the node a gate takes to their values ("": the first writer
    seen; declared by the node runtime, :mod:`stillframe.node_runtime.declarations`),
    ``defaults`` to the loop's node each names by default; ``token``: the run's (empty: none)."""

    def __init__(self, node: api.Node, pins: dict[str, str],
                 defaults: dict[str, str] | None = None, token: str = "") -> None:
        self.node = node
        self.gates: dict[str, WriterGate] = {}
        self.pins = dict(pins)
        self.defaults = defaults or {}
        self.token = token_suffix(token)
        self.samples_seen = False       # a gate has seen samples (:meth:`keep_graph_read`)
        self.next_graph_read = 0
        self.next_announce = 0
        self.announced: dict[str, list[str]] = {}     # topic -> the writers last logged

    def add(self, topic: str, parameter: str, *, stamped: bool = True) -> WriterGate:
        """The gate of ``topic``, taking the writers of the node ``parameter`` names, or, for a
        ``stamped`` topic (its messages have a header) of a run with a token, the samples that
        carry it."""
        gate = WriterGate(self.pins[parameter], graph_writers(self.node, topic),
                          count_writers=lambda: self.node.count_publishers(topic),
                          namespace=self.node.get_namespace(),
                          token=self.token if stamped else b"",
                          own=self.pins[parameter] or self.defaults.get(parameter, ""))
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

    def announce(self, log: Any) -> bool:
        """Log the writers refused since the last call, as soon as they are (at most every
        :data:`RECHECK_NS`), each once by the name the graph has for it; True when something new
        was logged (the node then publishes its status at once)."""
        if not any(gate.news for gate in self.gates.values()):
            return False
        now = time.monotonic_ns()
        if now < self.next_announce:
            return False
        self.next_announce = now + RECHECK_NS
        logged = False
        for topic, gate in self.gates.items():
            gate.news = False
            names = gate.ignored()
            if names and names != self.announced.get(topic):
                self.announced[topic] = names
                refused = sum(gate.rejected.values())
                kind = "a foreign writer (without the run's token)" if gate.token else (
                    "another writer")
                log.warning(f"{topic}: refusing the samples of {kind}: "
                            f"{', '.join(names)} ({refused} so far)")
                logged = True
        return logged

    def message(self) -> str:
        """Which second writers are being ignored, for the status message."""
        return "; ".join(
            f"{'foreign' if gate.token else 'second'} writer on {topic} ignored: "
            f"{', '.join(names)}" for topic, gate in self.gates.items()
            if (names := gate.ignored()))
