"""The declared base of the loop nodes (sim_node, estimator_node, controller_node) and of the
container that composes them: the cycle, the parameters, ``/diagnostics``, the writer gates, the
real-time practices and the lifecycle.

- :class:`Cycle`: spin → process → idle → housekeeping, until shutdown, then a last status;
  a node (or the container) says what each step is; idle and housekeeping wait while a sample
  is partly in (:meth:`Cycle.mid_sample`).
- :class:`LoopNode`: a :class:`Cycle` on one node, with its declared parameters
  (:data:`.declarations.NODE_PARAMETERS`, checked at start and at every set), ``/diagnostics``
  from :meth:`LoopNode.status`, the writer gates named by its ``*_writer`` parameters and the
  real-time practices of its ``rt`` parameters.
- :class:`Managed`: a managed (lifecycle) node's states around a :class:`LoopNode` class:
  unconfigured until ``configure`` builds the node from the scene, inactive, active, finalized
  (docs/nodes.md, lifecycle).
"""

from __future__ import annotations

import time
from typing import Any, ClassVar, TypeVar

from stillframe.contract.topics import DEFAULT_NAMESPACE
from stillframe.errors import InputError
from stillframe.loop.writer_gate import InputGates
from stillframe.middleware import api, lifecycle
from stillframe.middleware.params import Parameter, SetParametersResult
from stillframe.node_runtime.declarations import (
    NODE_PARAMETERS,
    WRITER_DEFAULTS,
    ManagedParameterValues,
    RealtimeParameterValues,
    TimingParameterValues,
)
from stillframe.node_runtime.parameters import (
    NodeParameters,
    current,
    declare,
    defaults,
    set_check,
)
from stillframe.node_runtime.phase_timing import MARKS, PhaseLog
from stillframe.node_runtime.realtime import (
    NO_PINNING,
    Realtime,
    RealtimeOptions,
    parse_practices,
    start_realtime,
)
from stillframe.node_runtime.support import Diagnostics, LoopParameters, declare_loop_parameters

__all__ = ["Cycle", "LoopNode", "Managed", "main", "realtime_options"]

N = TypeVar("N", bound="LoopNode")
P = TypeVar("P", bound=NodeParameters)
#: how long an idle managed node (not active yet, or finalized) waits in one spin [s]
IDLE_SPIN_S = 0.1


class Cycle:
    """spin → process → idle → housekeeping until shutdown (:meth:`run`)."""

    def start(self) -> None:
        """Before the first cycle (the peers of lock-step, the subscriptions)."""

    def spin(self, timeout_s: float) -> None:
        """Wait at most ``timeout_s`` [s] for the middleware and run what arrived."""
        raise NotImplementedError

    def next_wait(self) -> float:
        """The longest wait of the next spin [s]."""
        return IDLE_SPIN_S

    def process_ready(self) -> int:
        """Handle what is ready; how many samples were handled."""
        raise NotImplementedError

    def idle(self) -> None:
        """Between samples (the collector's work with the real-time practice ``gc``)."""

    def housekeeping(self) -> bool:
        """Between samples: watchdogs, graph reads, ``/diagnostics`` when due; whether a status
        was published."""
        return False

    def finish(self) -> None:
        """After the last cycle (a last status)."""

    def mid_sample(self) -> bool:
        """Whether a sample is partly in (some of its messages taken, not yet handled): the idle
        work and the housekeeping then wait until it is, off the sample's path."""
        return False

    def cycle(self) -> None:
        """One turn: spin, handle what is ready, then the idle work and the housekeeping unless a
        sample is only partly in."""
        self.spin(self.next_wait())
        if self.process_ready() or not self.mid_sample():
            self.idle()
            self.housekeeping()

    def run(self) -> None:
        """:meth:`start`, cycles until shutdown (SIGINT, SIGTERM, or
        :func:`~stillframe.middleware.api.shutdown`), then :meth:`finish`."""
        self.start()
        while api.ok():
            self.cycle()
        self.finish()


def realtime_options(values: RealtimeParameterValues) -> RealtimeOptions:
    """What a node's ``rt``, ``rt_priority``, ``rt_cpus`` and ``spin_margin_us`` ask for."""
    cpus = () if values.rt_cpus == [NO_PINNING] else tuple(values.rt_cpus)
    return RealtimeOptions(parse_practices(values.rt), values.rt_priority, cpus,
                           values.spin_margin_us)


class LoopNode(Cycle):
    """One loop node: its parameters, diagnostics, writer gates, real-time practices and cycle.

    A subclass names its node (:attr:`NAME`, whose declarations are
    :data:`.declarations.NODE_PARAMETERS`), the parameters that pin its writer gates
    (:attr:`WRITER_PINS`), applies its dynamic parameters (:meth:`apply`) and reports
    (:meth:`status`)."""

    NAME: ClassVar[str]
    WRITER_PINS: ClassVar[tuple[str, ...]] = ()
    MANAGED: ClassVar[bool] = False

    def __init__(self, node: api.Node, params: LoopParameters,
                 values: dict[type, NodeParameters] | None = None) -> None:
        self.node = node
        self.params = params
        self.values = values or {}
        pins = {name: getattr(v, name) for v in self.values.values()
                for name in self.WRITER_PINS if hasattr(v, name)}
        self.gates = InputGates(node, {name: pins.get(name, "") for name in self.WRITER_PINS},
                                WRITER_DEFAULTS, params.run_token)
        self.diagnostics = Diagnostics(node, params.diagnostics_period_s)
        self.rt = Realtime(RealtimeOptions())   # enter_realtime() applies what was asked
        self.activated = True                      # lifecycle: inactive nodes do not act
        timing = self.setting(TimingParameterValues)
        #: the phases of every sample (:mod:`.phase_timing`), written to ``phase_log`` at the end
        self.timing = PhaseLog(self.NAME, MARKS[self.NAME], enabled=timing.phase_timing)
        self.slot = self.timing.slots
        self.phase_log = timing.phase_log
        #: when the last sample began in this node (monotonic ns): its first message
        self.sample_start_ns = 0

    # -- parameters ----------------------------------------------------------------------
    @classmethod
    def declarations(cls, scene: Any) -> tuple[type[NodeParameters], ...]:
        """The node's declarations beyond the loop's (the scene may leave some out)."""
        return NODE_PARAMETERS[cls.NAME][1:]

    @classmethod
    def declare(cls, node: api.Node) -> tuple[LoopParameters, dict[type, NodeParameters]]:
        """Declare every parameter of the node, each checked by its declaration (InputError
        naming the first wrong one); the scene is loaded once its parameters are known."""
        params = declare_loop_parameters(node)
        values = {c: declare(node, c, params.scene) for c in cls.declarations(params.scene)}
        return params, values

    @classmethod
    def build(cls: type[N], node: api.Node) -> N:
        """The node from its parameters (not in real time yet: :meth:`enter_realtime`)."""
        params, values = cls.declare(node)
        loop = cls(node, params, values)
        node.add_on_set_parameters_callback(loop.on_set_parameters)
        return loop

    def setting(self, cls: type[P]) -> P:
        """The node's values of the declarations ``cls`` (their defaults for the scene when the
        node was made without them, as a test makes it)."""
        return self.values.get(cls) or defaults(cls, self.params.scene)  # type: ignore[return-value]

    def on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """The declarations' check (read-only and undeclared refused, values checked), then
        :meth:`apply`."""
        result = set_check(*self.values)(parameters)
        return self.apply(parameters) if result.successful else result

    def apply(self, parameters: list[Parameter]) -> SetParametersResult:
        """Put checked dynamic parameters into effect (all or none)."""
        return SetParametersResult(True)

    def enter_realtime(self) -> None:
        """Apply the real-time practices the parameters ask for, hold the collector (always:
        :meth:`.realtime.Realtime.hold_collector`), and log what took effect."""
        self.rt = start_realtime(self.node, realtime_options(
            self.setting(RealtimeParameterValues)), collector=True)

    # -- lifecycle -----------------------------------------------------------------------
    def activate(self) -> None:
        """``activate``: the node acts on its samples again."""
        self.activated = True

    def deactivate(self) -> None:
        """``deactivate``: the node keeps spinning and reporting but does not act on samples."""
        self.activated = False

    def reset(self) -> None:
        """``cleanup``: forget the run (a new estimator or controller from the scene)."""

    # -- the cycle -----------------------------------------------------------------------
    def spin(self, timeout_s: float) -> None:
        """One ``spin_once`` of the node, at most ``timeout_s`` [s]."""
        self.node.spin_once(timeout_s)

    def idle(self) -> None:
        """The collector's work when the next sample leaves time for it (:meth:`slack_ns`)."""
        self.rt.idle(self.slack_ns(time.monotonic_ns()))
        self.timing.mark(self.slot["collected"])

    def slack_ns(self, now_ns: int) -> int | None:
        """Real time: how long before the next sample is due here, one period after the start
        of the last one (:attr:`sample_start_ns`); None in lock-step (no deadline) or when no
        sample came for two periods (the loop is not running)."""
        period_ns = round(self.params.period * 1e9)
        if self.params.lockstep or now_ns - self.sample_start_ns > 2 * period_ns:
            return None
        return self.sample_start_ns + period_ns - now_ns

    def housekeeping(self) -> bool:
        """The watchdog, the graph reads and ``/diagnostics`` when due; the sample's phase row
        closes after them."""
        self.gates.keep_graph_read()
        self.check()
        if published := self.status_due():
            self.publish_status()
        self.timing.end(self.slot["done"])
        return published

    def status_due(self) -> bool:
        """A writer gate has news, or the periodic status is due (:meth:`.support.Diagnostics.due`
        with the time left before the next sample)."""
        return (self.gates.announce(self.node.get_logger())
                or self.diagnostics.due(self.slack_ns(time.monotonic_ns())))

    def check(self) -> None:
        """Every cycle not in the middle of a sample, before the status (the controller's
        watchdog)."""

    def status(self) -> tuple[dict[str, Any], int, str]:
        """``/diagnostics``: the values, the level and the message."""
        raise NotImplementedError

    def status_stamp(self) -> int:
        """The stamp of the status [ns]: the newest sample handled."""
        return 0

    def publish_status(self) -> None:
        """Publish the node's ``/diagnostics`` (:meth:`status`, plus the lifecycle state of a
        managed node), stamped with :meth:`status_stamp`."""
        values, level, message = self.status()
        if self.node_is_managed():
            values = {**values, "lifecycle": "active" if self.activated else "inactive"}
        self.diagnostics.publish(self.status_stamp(), values, level, message)

    def node_is_managed(self) -> bool:
        """Whether the node runs under the lifecycle: its class is :attr:`MANAGED` and the
        middleware node is a managed one."""
        return self.MANAGED and hasattr(self.node, "lifecycle_state")

    def finish(self) -> None:
        """A last status, and the phase log written (:meth:`write_phases`)."""
        self.publish_status()
        self.write_phases()

    def write_phases(self) -> None:
        """The phase ring to ``phase_log`` (when given), with the practices in effect."""
        if self.phase_log:
            self.timing.write(self.phase_log, {
                "mode": self.params.mode, "period_ns": round(self.params.period * 1e9),
                "rt_applied": self.rt.applied, "rt_refused": self.rt.refused})


class Managed(Cycle):
    """A managed node (rcl_lifecycle's states, docs/nodes.md): parameters declared at start;
    ``configure`` builds the node (``cleanup`` and a later ``configure`` start it afresh);
    ``activate`` and ``deactivate`` switch what it does (:meth:`LoopNode.deactivate`); the
    cycle starts (the lock-step wait for the peers, the subscriptions) at the first
    activation. With ``autostart`` (the default) the node configures and activates itself."""

    def __init__(self, cls: type[LoopNode], node: api.ManagedNode, *,
                 realtime: bool = True) -> None:
        self.cls = cls
        self.node = node
        self.realtime = realtime    # enter the node's real-time practices when configured
        self.params, self.values = cls.declare(node)
        self.loop: LoopNode | None = None
        self.started = False
        node.manage(self.on_transition)
        node.add_on_set_parameters_callback(self.on_set_parameters)

    def on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """The declarations' check; the node applies what passes once configured (before, the
        values wait for ``configure``)."""
        if self.loop is not None:
            return self.loop.on_set_parameters(parameters)
        return set_check(*self.values)(parameters)

    def on_transition(self, name: str) -> str:
        """The callback of every transition (:data:`.lifecycle.TransitionCallback`)."""
        log = self.node.get_logger()
        try:
            if name == "configure":
                if self.loop is None:
                    self.values = {c: current(self.node, c) for c in self.values}
                    self.loop = self.cls(self.node, self.params, self.values)
                    if self.realtime:
                        self.loop.enter_realtime()
                    self.loop.deactivate()
                else:
                    self.loop.reset()
            elif name == "activate" and self.loop is not None:
                self.loop.activate()
            elif name in ("deactivate", "cleanup", "shutdown", "error") and self.loop:
                self.loop.deactivate()
                if name == "cleanup":
                    self.loop.reset()
        except InputError as exc:
            log.error(f"{name}: {exc}")
            return lifecycle.FAILURE
        except Exception as exc:    # anything else is rcl_lifecycle's error: errorprocessing
            log.error(f"{name}: {type(exc).__name__}: {exc}")
            return lifecycle.ERROR
        log.info(f"lifecycle: {name} done")
        return lifecycle.SUCCESS

    def autostart(self) -> None:
        """:meth:`bring_up` now when the ``autostart`` parameter says so."""
        if self.values[ManagedParameterValues].autostart:  # type: ignore[attr-defined]
            self.bring_up()

    def bring_up(self) -> LoopNode:
        """``configure`` and ``activate``; the node (InputError when a transition fails)."""
        for transition in ("configure", "activate"):
            if self.node.trigger(transition) != lifecycle.SUCCESS:
                raise InputError(f"{self.cls.NAME}: {transition} failed (see the log)")
        assert self.loop is not None
        return self.loop

    def spin(self, timeout_s: float) -> None:
        """One ``spin_once`` of the node, at most ``timeout_s`` [s]."""
        self.node.spin_once(timeout_s)

    def cycle(self) -> None:
        """While unconfigured or not yet active, serve the services only; from the first activation
        on, the node's own cycle (started once)."""
        if self.loop is None or not (self.started or self.loop.activated):
            self.spin(IDLE_SPIN_S)      # unconfigured, or not active yet: the services only
            return
        if not self.started:
            self.loop.start()
            self.started = True
        self.loop.cycle()

    def finish(self) -> None:
        """The node's :meth:`LoopNode.finish` if it ever started."""
        if self.started and self.loop is not None:
            self.loop.finish()


def main(cls: type[LoopNode]) -> int:
    """Run the node of ``cls`` (a console script's ``main``): created (managed when the class
    is), its parameters declared, its cycle until SIGINT or SIGTERM."""
    node = api.create_node(cls.NAME, namespace=DEFAULT_NAMESPACE, managed=cls.MANAGED)
    try:
        if cls.MANAGED:
            managed = Managed(cls, node)  # type: ignore[arg-type]
            managed.autostart()
            managed.run()
        else:
            loop = cls.build(node)
            loop.enter_realtime()
            loop.run()
    finally:
        node.destroy_node()
    return 0
