"""Command-path integrity: which actuator commands the simulator takes (issue 11, item 4).

One :class:`CommandGate` per command topic. A command is taken only from *the* command writer,
identified by its writer GID (the DDS publication GUID the middleware hands with each sample):
the first writer seen, or, when ``pinned`` names a node, the writer whose node has that name in
the ROS graph. Any other writer is a second writer: it is reported (:meth:`CommandGate.report`)
and its samples are ignored. Commands from the command writer are rejected, and counted by
reason, when their value is not finite or beyond the actuator's limit (:data:`HARD_LIMIT`
without one), or their stamp lies in the future of the current sample or before the command
already held; commands for an actuator the scene's controller does not drive are refused.

Where the middleware gives no writer GID (real rclpy Jazzy: its message info has none), the gate
cannot tell samples apart: while the graph shows more than one writer on the topic it rejects
every command (``ambiguous_writer``), so the simulator holds its safe state (docs/reliability.md).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

#: reasons a command is rejected, in the order they are checked
REASONS = ("inactive_actuator", "second_writer", "unknown_writer", "ambiguous_writer",
           "non_finite", "beyond_limit", "future_stamp", "past_stamp")

#: the bound on a command when the actuator has no limit (N m or N; far beyond any rig's
#: actuator, it keeps values like 1e308 from reaching the integrator)
HARD_LIMIT = 1e6

#: (writer GID, node namespace/name) of the topic's current writers, from the ROS graph
GraphWriters = Callable[[], list[tuple[bytes, str]]]


@dataclass
class CommandGate:
    """The accept/reject decision for one command topic.

    ``limit``: the actuator's saturation (None: :data:`HARD_LIMIT`); ``active``: whether the
    scene's controller drives this actuator (commands for the other one are refused);
    ``pinned``: the node name (``name`` or ``/namespace/name``) allowed to command, empty for the
    first writer seen; ``writers``: the topic's writers in the graph (to resolve a GID to its
    node name and to count writers).
    """

    limit: float | None
    pinned: str
    writers: GraphWriters
    active: bool = True
    owner: bytes = b""
    rejected: Counter = field(default_factory=Counter)
    intruders: set[bytes] = field(default_factory=set)

    def node_of(self, gid: bytes) -> str | None:
        """The node of writer ``gid`` in the graph; None while its node is not known."""
        return next((name for g, name in self.writers() if g == gid and name.strip("/")), None)

    def name_of(self, gid: bytes) -> str:
        return self.node_of(gid) or gid.hex()

    def is_owner(self, gid: bytes) -> str | None:
        """None when ``gid`` may command, else the reason it may not."""
        if not gid:
            return "ambiguous_writer" if len(self.writers()) > 1 else None
        if gid == self.owner:
            return None
        if self.owner:
            self.intruders.add(gid)
            return "second_writer"
        if self.pinned:
            name = self.node_of(gid)
            if name is None:
                return "unknown_writer"     # not in the graph yet: cannot check its name
            if name != self.pinned and name.rsplit("/", 1)[-1] != self.pinned:
                self.intruders.add(gid)
                return "second_writer"
        self.owner = gid
        return None

    def check(self, value: float, stamp_ns: int, gid: bytes, now_ns: int, held_ns: int) -> bool:
        """Whether the command ``value`` stamped ``stamp_ns`` from writer ``gid`` is taken at
        sample ``now_ns`` with the command stamped ``held_ns`` held; counts the reason if not."""
        reason = "inactive_actuator" if not self.active else self.is_owner(gid)
        if reason is None:
            if not math.isfinite(value):
                reason = "non_finite"
            elif abs(value) > (HARD_LIMIT if self.limit is None else self.limit):
                reason = "beyond_limit"
            elif stamp_ns > now_ns:
                reason = "future_stamp"
            elif stamp_ns < held_ns:
                reason = "past_stamp"
        if reason is not None:
            self.rejected[reason] += 1
            return False
        return True

    def ignored(self) -> list[str]:
        """The second writers seen, by node name (by GID while the name is not known)."""
        return sorted(self.name_of(gid) for gid in self.intruders)

    def report(self) -> dict[str, object]:
        """For ``/diagnostics``: the writer taken, the writers ignored, rejections by reason."""
        return {"writer": self.name_of(self.owner) if self.owner else "",
                "ignored_writers": ",".join(self.ignored()),
                **{f"rejected_{r}": self.rejected[r] for r in REASONS}}
