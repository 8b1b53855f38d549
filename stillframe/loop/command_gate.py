"""Command-path integrity: which actuator commands the simulator takes.

One :class:`CommandGate` per command topic. A command is taken only from *the* command writer,
decided by a :class:`stillframe.loop.writer_gate.WriterGate`: with the run's token, the commands
that carry it (the loop's controller's); without one, the writers of one node (the first writer
seen, or the node ``command_writer`` names). Any other writer is reported and its samples are
ignored. Commands from the command writer are rejected, and counted by reason, when their value
is not finite or beyond the command's bound (the actuator's limit, or
:data:`stillframe.config.loop_sections.COMMAND_BOUND` without one), or their stamp lies in the
future of the current sample or before the command already held; commands for an actuator the
scene's controller does not drive are refused.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from stillframe.loop import writer_gate
from stillframe.loop.writer_gate import WriterGate

#: reasons a command is rejected, in the order they are checked
REASONS = ("inactive_actuator", *writer_gate.REASONS, "non_finite", "beyond_limit",
           "future_stamp", "past_stamp")


@dataclass
class CommandGate:
    """The accept/reject decision for one command topic.

    ``bound``: the largest magnitude taken; ``writer``: the topic's writer gate (None: every
    writer is the command writer, as in the one-process loop); ``active``: whether the scene's
    controller drives this actuator (commands for the other one are refused).
    """

    bound: float
    writer: WriterGate | None
    active: bool = True
    rejected: Counter = field(default_factory=Counter)

    def admits(self, gid: bytes, sequence: int = 0, data: bytes | memoryview = b"") -> bool:
        """Whether writer ``gid`` (or, without one, the writer that numbered the sample
        ``sequence``; with the run's token, the sample's CDR ``data`` carrying it) may command
        this actuator (checked before the sample is decoded); counts the reason if not (the
        writer's reasons in the writer gate)."""
        if self.active:
            return self.writer is None or self.writer.admits(gid, sequence, data)
        self.rejected["inactive_actuator"] += 1
        return False

    def check(self, value: float, stamp_ns: int, now_ns: int, held_ns: int) -> bool:
        """Whether the command ``value`` stamped ``stamp_ns`` (from an admitted writer) is taken
        at sample ``now_ns`` with the command stamped ``held_ns`` held; counts the reason if not."""
        if not math.isfinite(value):
            reason = "non_finite"
        elif abs(value) > self.bound:
            reason = "beyond_limit"
        elif stamp_ns > now_ns:
            reason = "future_stamp"
        elif stamp_ns < held_ns:
            reason = "past_stamp"
        else:
            return True
        self.rejected[reason] += 1
        return False

    def report(self) -> dict[str, object]:
        """For ``/diagnostics``: the writer taken, the writers ignored, rejections by reason."""
        own = {f"rejected_{r}": self.rejected[r] for r in REASONS if r not in writer_gate.REASONS}
        return {**(self.writer.report() if self.writer is not None else {}), **own}
