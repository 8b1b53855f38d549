"""Managed (lifecycle) nodes: rcl_lifecycle's default state machine as data, and its four
``lifecycle_msgs`` services' answers for the ``dds`` backend (the ``rclpy`` backend runs rclpy's
own ``rclpy.lifecycle.LifecycleNode``).

States, transitions, ids and labels are rcl_lifecycle's (``lifecycle_msgs/msg/State`` and
``Transition``): a primary state (unconfigured, inactive, active, finalized) is left by a public
transition (configure, cleanup, activate, deactivate, shutdown) into a transition state
(configuring ...), whose callback's answer (``transition_success``, ``_failure``, ``_error``)
gives the next primary state; an error passes through ``errorprocessing``. A transition not
available in the current state is refused with rcl_lifecycle's reason and changes nothing.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, NamedTuple

from stillframe.contract import messages
from stillframe.errors import InputError

UNKNOWN, UNCONFIGURED, INACTIVE, ACTIVE, FINALIZED = 0, 1, 2, 3, 4
CONFIGURING, CLEANINGUP, SHUTTINGDOWN, ACTIVATING, DEACTIVATING, ERRORPROCESSING = range(10, 16)
STATE_LABELS = {UNKNOWN: "unknown", UNCONFIGURED: "unconfigured", INACTIVE: "inactive",
                ACTIVE: "active", FINALIZED: "finalized", CONFIGURING: "configuring",
                CLEANINGUP: "cleaningup", SHUTTINGDOWN: "shuttingdown",
                ACTIVATING: "activating", DEACTIVATING: "deactivating",
                ERRORPROCESSING: "errorprocessing"}
#: the outcomes of a transition's callback, by the label of the transition they trigger
SUCCESS, FAILURE, ERROR = "transition_success", "transition_failure", "transition_error"


class Transition(NamedTuple):
    """One edge of the state machine (``lifecycle_msgs/msg/TransitionDescription``)."""

    id: int
    label: str
    start: int
    goal: int


def _outcomes(base: int, state: int, success: int, failure: int, error: int) -> list[Transition]:
    return [Transition(base, SUCCESS, state, success),
            Transition(base + 1, FAILURE, state, failure),
            Transition(base + 2, ERROR, state, error)]


#: rcl_lifecycle's default transition graph, in its order
GRAPH: tuple[Transition, ...] = (
    Transition(1, "configure", UNCONFIGURED, CONFIGURING),
    *_outcomes(10, CONFIGURING, INACTIVE, UNCONFIGURED, ERRORPROCESSING),
    Transition(2, "cleanup", INACTIVE, CLEANINGUP),
    *_outcomes(20, CLEANINGUP, UNCONFIGURED, INACTIVE, ERRORPROCESSING),
    Transition(3, "activate", INACTIVE, ACTIVATING),
    *_outcomes(30, ACTIVATING, ACTIVE, INACTIVE, ERRORPROCESSING),
    Transition(4, "deactivate", ACTIVE, DEACTIVATING),
    *_outcomes(40, DEACTIVATING, INACTIVE, ACTIVE, ERRORPROCESSING),
    Transition(5, "shutdown", UNCONFIGURED, SHUTTINGDOWN),
    Transition(6, "shutdown", INACTIVE, SHUTTINGDOWN),
    Transition(7, "shutdown", ACTIVE, SHUTTINGDOWN),
    *_outcomes(50, SHUTTINGDOWN, FINALIZED, FINALIZED, ERRORPROCESSING),
    *_outcomes(60, ERRORPROCESSING, UNCONFIGURED, FINALIZED, FINALIZED),
)
#: the public transitions (what ``stillframe lifecycle set`` and ``ros2 lifecycle set`` take)
PUBLIC = ("configure", "cleanup", "activate", "deactivate", "shutdown")
#: the primary states' transitions' callbacks are named after the transition state
CALLBACK_OF = {CONFIGURING: "configure", CLEANINGUP: "cleanup", SHUTTINGDOWN: "shutdown",
               ACTIVATING: "activate", DEACTIVATING: "deactivate", ERRORPROCESSING: "error"}

#: ``on_transition(name) -> outcome``: ``name`` one of :data:`CALLBACK_OF`'s values, the
#: outcome :data:`SUCCESS`, :data:`FAILURE` or :data:`ERROR` (an exception counts as ERROR)
TransitionCallback = Callable[[str], str]
#: the lifecycle services of a managed node, under its name, with their types
SERVICES = {"get_state": "GetState", "change_state": "ChangeState",
            "get_available_states": "GetAvailableStates",
            "get_available_transitions": "GetAvailableTransitions",
            "get_transition_graph": "GetAvailableTransitions"}
TRANSITION_EVENT = "~/transition_event"


class TransitionRefusedError(InputError):
    """A transition that is not available in the current state (rcl_lifecycle's reason)."""


class StateMachine:
    """One managed node's state and its transitions (the ``dds`` backend's rcl_lifecycle)."""

    def __init__(self, on_transition: TransitionCallback,
                 on_event: Callable[[Transition], None] | None = None) -> None:
        self.state = UNCONFIGURED
        self.on_transition = on_transition
        self.on_event = on_event or (lambda _: None)

    @property
    def label(self) -> str:
        """The current state's label as ``ros2 lifecycle get`` prints it (``unconfigured``,
        ``inactive``, ``active``, ``finalized`` or a transition state)."""
        return STATE_LABELS[self.state]

    def available(self) -> list[Transition]:
        """The transitions that start in the current state (what ``~/get_available_transitions``
        answers)."""
        return [t for t in GRAPH if t.start == self.state]

    def find(self, transition_id: int = 0, label: str = "") -> Transition:
        """The transition of the current state with ``label`` (if given) or ``transition_id``;
        :class:`TransitionRefusedError` with rcl_lifecycle's reason otherwise."""
        for t in self.available():
            if (t.label == label) if label else (t.id == transition_id):
                return t
        raise TransitionRefusedError(f"No transition matching {label or transition_id} found for "
                                f"current state {self.label}")

    def _step(self, transition: Transition) -> None:
        start = self.state
        self.state = transition.goal
        self.on_event(transition._replace(start=start))

    def change(self, transition_id: int = 0, label: str = "") -> str:
        """Run a public transition: into its transition state, the callback, on to the primary
        state its outcome gives (through ``errorprocessing`` on an error). The outcome;
        :class:`TransitionRefusedError` when not available (nothing changes)."""
        self._step(self.find(transition_id, label))
        outcome = self._callback()
        self._step(self.find(label=outcome))
        if outcome == ERROR:
            self._step(self.find(label=self._callback()))
        return outcome

    def _callback(self) -> str:
        try:
            outcome = self.on_transition(CALLBACK_OF[self.state])
        except Exception:
            return ERROR
        return outcome if outcome in (SUCCESS, FAILURE, ERROR) else ERROR


def state_msg(state: int) -> Any:
    """The ``lifecycle_msgs/msg/State`` of state id ``state``, with its label."""
    return messages.new("lifecycle_msgs/msg/State", id=state, label=STATE_LABELS[state])


def transition_msg(t: Transition) -> Any:
    """The ``lifecycle_msgs/msg/Transition`` of ``t``: its id and label."""
    return messages.new("lifecycle_msgs/msg/Transition", id=t.id, label=t.label)


def description_msg(t: Transition) -> Any:
    """The ``lifecycle_msgs/msg/TransitionDescription`` of ``t``: the transition with its start and
    goal states."""
    return messages.new("lifecycle_msgs/msg/TransitionDescription", transition=transition_msg(t),
                        start_state=state_msg(t.start), goal_state=state_msg(t.goal))


def event_msg(t: Transition) -> Any:
    """The ``~/transition_event`` message of a step (stamped now, in ns, as rcl_lifecycle)."""
    return messages.new("lifecycle_msgs/msg/TransitionEvent", timestamp=time.time_ns(),
                        transition=transition_msg(t), start_state=state_msg(t.start),
                        goal_state=state_msg(t.goal))


def answers(machine: StateMachine, log: Callable[[str], None]) -> dict[str, Callable]:
    """The four services' (and ``get_transition_graph``'s) answers on ``machine``, by service
    name; a refused change is logged with its reason, as rclcpp and rcl_lifecycle log it."""
    def response(service: str, **fields: Any) -> Any:
        return messages.new(f"lifecycle_msgs/srv/{SERVICES[service]}_Response", **fields)

    def change_state(request: Any) -> Any:
        t = request.transition
        try:
            outcome = machine.change(t.id, t.label)
        except TransitionRefusedError as exc:
            log(f"Unable to start transition {t.label or t.id} from current state "
                f"{machine.label}: {exc}")
            return response("change_state", success=False)
        return response("change_state", success=outcome == SUCCESS)

    return {
        "get_state": lambda _: response("get_state", current_state=state_msg(machine.state)),
        "change_state": change_state,
        "get_available_states": lambda _: response(
            "get_available_states", available_states=[state_msg(s) for s in STATE_LABELS]),
        "get_available_transitions": lambda _: response(
            "get_available_transitions",
            available_transitions=[description_msg(t) for t in machine.available()]),
        "get_transition_graph": lambda _: response(
            "get_transition_graph", available_transitions=[description_msg(t) for t in GRAPH]),
    }
