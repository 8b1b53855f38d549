"""Whether a run's result can be trusted: the *degraded* verdict.

A run whose control path failed still ends with its table of reductions; the figures are then
the held, zeroed, refused or clipped commands', not the controller's. :func:`verdict` reads the
evaluation (sim_node's, or the one-process loop's) and the controller's counters (its last
``/diagnostics``, or the one-process loop's ``controller``) and gives the reasons, each a short
text with its count; an empty list is a run to trust. In every mode:

- the simulator refused commands of the loop's controller (a bad value or stamp; another
  writer's refused commands are not the run's figures, :func:`foreign_writers` names them);
- the control law's output went beyond :data:`~stillframe.control.supervisor.RUNAWAY_FACTOR`
  times the command's bound, and was clipped to it (``runaway``: an estimate or a design that no
  longer matches the plant, or a plant driven far beyond what the rig can do);

and in real time:

- more than :data:`DEADLINE_MISS_LIMIT` of the samples missed their command's deadline (and when
  the simulator ran without ``SCHED_FIFO``, that, why, and the real-time practice as the fix);
- the controller's watchdog sent zero commands (its estimates fell behind);
- the controller never commanded in time (no sample had its command before its deadline);
- most samples were degraded: the simulator applied zero (the safe state after the command
  timeout, or the miss-rate guard).

``stillframe launch`` and ``stillframe closed-loop`` print the reasons on one warning line and
add ``"degraded"`` and ``"degraded_reasons"`` to their JSON; ``launch --strict`` then exits with
:class:`~stillframe.errors.DegradedRunError`'s code. A run, in either mode, whose gates refused
the samples of writers not of the run (:func:`foreign_writers`) ends with a warning line naming
them, ``"foreign_writers"`` in its JSON, and exits 0 (its figures are its own nodes': a lock-step
run bit for bit the clean run's), 6 with ``--strict``.
"""

from __future__ import annotations

from typing import Any

from stillframe.contract.topics import CONTRACT, DEFAULT_NAMESPACE
from stillframe.control.supervisor import RUNAWAY_FACTOR
from stillframe.loop.writer_gate import REASONS, same_node
from stillframe.middleware.graph import fqn
from stillframe.middleware.names import resolve_topic
from stillframe.node_runtime.declarations import CONTROLLER, SIM
from stillframe.node_runtime.realtime import LIMITS_HINT

#: the share of a run's samples that may miss their deadline before the run is degraded
DEADLINE_MISS_LIMIT = 0.01


def watchdog_zeros(statuses: dict[str, dict[str, str]]) -> int | None:
    """The zero commands controller_node's watchdog sent (its last ``/diagnostics``); None
    without a status of it."""
    return next((int(values["watchdog"]) for name, values in statuses.items()
                 if same_node(name, CONTROLLER, DEFAULT_NAMESPACE) and "watchdog" in values),
                None)


def controller_count(evaluation: dict[str, Any], statuses: dict[str, dict[str, str]],
                     key: str) -> int:
    """A counter of the controller: the one-process loop's (``evaluation["controller"]``), else
    controller_node's last ``/diagnostics``; 0 without either."""
    if isinstance(own := evaluation.get("controller"), dict) and key in own:
        return int(own[key])
    return next((int(values[key]) for name, values in statuses.items()
                 if same_node(name, CONTROLLER, DEFAULT_NAMESPACE) and key in values), 0)


def without_fifo(evaluation: dict[str, Any]) -> str:
    """When the simulator ran without ``SCHED_FIFO`` (its ``realtime`` report): that, why, and
    the real-time practice as the fix; "" when it had it or did not report."""
    practices = evaluation.get("realtime")
    if not isinstance(practices, dict) or any(
            str(a).startswith("SCHED_FIFO") for a in practices.get("applied", ())):
        return ""
    why = next((str(r) for r in practices.get("refused", ()) if "SCHED_FIFO" in str(r)),
               "SCHED_FIFO not asked for (--rt)")
    return (f", the nodes without SCHED_FIFO ({why}): the fix is the real-time practice, "
            f"{LIMITS_HINT}")


def verdict(evaluation: dict[str, Any], statuses: dict[str, dict[str, str]]) -> list[str]:
    """The reasons a run is degraded (module docstring); [] for a run to trust."""
    steps = max(int(evaluation.get("steps", 0)), 1)
    reasons = []
    if refused := int(evaluation.get("rejected_commands", 0)) - writer_refusals(evaluation):
        reasons.append(f"{refused} refused commands")
    if runaway := controller_count(evaluation, statuses, "runaway"):
        reasons.append(f"{runaway} commands of the law beyond {RUNAWAY_FACTOR:g} times their "
                       "bound, clipped to it")
    if evaluation.get("mode", "lockstep") != "realtime":
        return reasons
    misses = int(evaluation.get("deadline_misses", 0))
    if misses > DEADLINE_MISS_LIMIT * steps:
        reasons.append(f"{misses} deadline misses ({100 * misses / steps:.1f} % of {steps} "
                       f"samples, over {100 * DEADLINE_MISS_LIMIT:g} %)" + without_fifo(evaluation))
    if zeros := watchdog_zeros(statuses):
        reasons.append(f"{zeros} watchdog zeros")
    if "reduction_pct" in evaluation and not evaluation.get("commands_in_time", 1):
        reasons.append("the controller never commanded in time")
    zeroed = int(evaluation.get("degraded_samples", 0)) + int(
        evaluation.get("safe_state_samples", 0))
    if zeroed > steps / 2:
        reasons.append(f"{zeroed} of {steps} samples degraded (zero actuation applied)")
    return reasons


def writer_refusals(evaluation: dict[str, Any]) -> int:
    """The commands the simulator refused for their writer (another writer's, a foreign one's:
    :func:`foreign_writers` reports them), not for their value or stamp."""
    return sum(int(report.get(f"rejected_{r}", 0))
               for report in evaluation.get("command_gates", {}).values() for r in REASONS)


def _topic_keys() -> dict[str, str]:
    """The key prefix of each contract topic in a node's gate reports, to its full name."""
    return {spec.name.strip("/").replace("/", "_"): resolve_topic(spec.name, DEFAULT_NAMESPACE)
            for spec in CONTRACT}


def foreign_writers(evaluation: dict[str, Any],
                    statuses: dict[str, dict[str, str]]) -> list[dict[str, Any]]:
    """The writers the loop's gates refused (without the run's token, or, in a run without one,
    another node's), per node and topic: ``{"node", "topic", "writers", "refused"}``, the writers
    fully qualified as the graph names them. The simulator's from its result (its command
    gates), the other nodes' from their last ``/diagnostics``; [] for a run no writer but its
    own reached."""
    keys = _topic_keys()
    sim = fqn(DEFAULT_NAMESPACE, SIM)
    gates = evaluation.get("command_gates", {})
    reports = [(sim, keys[topic.strip("/").replace("/", "_")], report)
               for topic, report in gates.items()]
    reports += [(node, name, {k.removeprefix(f"{key}_"): v for k, v in values.items()
                              if k.startswith(f"{key}_")})
                for node, values in statuses.items() if not (node == sim and gates)
                for key, name in keys.items() if f"{key}_ignored_writers" in values]
    found = []
    for node, topic, report in reports:
        if refused := sum(int(report.get(f"rejected_{r}", 0)) for r in REASONS):
            writers = [w for w in str(report.get("ignored_writers", "")).split(",") if w]
            found.append({"node": node, "topic": topic, "writers": writers or ["unnamed"],
                          "refused": refused})
    return found


def foreign_warning(found: list[dict[str, Any]]) -> str:
    """One line on :func:`foreign_writers`: who wrote where, refused how often by whom."""
    return ("samples of writers not of this run refused (the figures are the loop's own "
            "nodes'): " + "; ".join(
                f"{' and '.join(f['writers'])} on {f['topic']} ({f['refused']} refused by "
                f"{f['node']})" for f in found))
