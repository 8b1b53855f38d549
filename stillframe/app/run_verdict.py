"""Whether a real-time run's result can be trusted (issue 26): the *degraded* verdict.

A real-time run whose control path failed still ends with its table of reductions; the figures
are then the held, zeroed or refused commands', not the controller's. :func:`verdict` reads the
evaluation sim_node wrote and the last ``/diagnostics`` of the nodes and gives the reasons, each
a short text with its count; an empty list is a run to trust. The reasons:

- more than :data:`DEADLINE_MISS_LIMIT` of the samples missed their command's deadline;
- the controller's watchdog sent zero commands (its estimates fell behind);
- the simulator refused commands (another writer, a bad value or stamp);
- the controller never commanded in time (no sample had its command before its deadline);
- most samples were degraded: the simulator applied zero (the safe state after the command
  timeout, or the miss-rate guard).

``stillframe launch`` prints the reasons on one warning line, adds ``"degraded"`` and
``"degraded_reasons"`` to its JSON, and with ``--strict`` exits with
:class:`~stillframe.errors.DegradedRunError`'s code.
"""

from __future__ import annotations

from typing import Any

from stillframe.loop.writer_gate import same_node

#: the share of a run's samples that may miss their deadline before the run is degraded
DEADLINE_MISS_LIMIT = 0.01


def watchdog_zeros(statuses: dict[str, dict[str, str]]) -> int | None:
    """The zero commands controller_node's watchdog sent (its last ``/diagnostics``); None
    without a status of it."""
    return next((int(values["watchdog"]) for name, values in statuses.items()
                 if same_node(name, "controller_node") and "watchdog" in values), None)


def verdict(evaluation: dict[str, Any], statuses: dict[str, dict[str, str]]) -> list[str]:
    """The reasons a real-time run is degraded (module docstring); [] for a run to trust or a
    lock-step run (its figures are the one-process loop's, however long it waited)."""
    if evaluation.get("mode") != "realtime":
        return []
    steps = max(int(evaluation.get("steps", 0)), 1)
    reasons = []
    misses = int(evaluation.get("deadline_misses", 0))
    if misses > DEADLINE_MISS_LIMIT * steps:
        reasons.append(f"{misses} deadline misses ({100 * misses / steps:.1f} % of {steps} "
                       f"samples, over {100 * DEADLINE_MISS_LIMIT:g} %)")
    if zeros := watchdog_zeros(statuses):
        reasons.append(f"{zeros} watchdog zeros")
    if refused := int(evaluation.get("rejected_commands", 0)):
        reasons.append(f"{refused} refused commands")
    if "reduction_pct" in evaluation and not evaluation.get("commands_in_time", 1):
        reasons.append("the controller never commanded in time")
    zeroed = int(evaluation.get("degraded_samples", 0)) + int(
        evaluation.get("safe_state_samples", 0))
    if zeroed > steps / 2:
        reasons.append(f"{zeroed} of {steps} samples degraded (zero actuation applied)")
    return reasons
