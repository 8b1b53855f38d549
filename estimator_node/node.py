"""estimator_node: the scene's estimator on the topic contract (docs/nodes.md).

A thin shell around :func:`stillframe.estimation.factory.make_estimator`. It collects the readings
of one stamp t_k from the floor IMUs, the encoder and the load cell (and ``state_truth`` for the
``truth`` estimator), then calls ``step(sample, command in effect)`` and publishes
``state_estimate`` and ``state_estimate/covariance`` stamped t_k. The actuation in effect is what
the simulator reports it applied over the previous period (after saturation and slew limits): the
encoder's ``effort`` (hinge torque) and ``floor3/load_cell`` (floor-3 force), so that a saturated
actuator does not wind the estimate up. Where a sample's reading was lost on the way: the command in
effect received on ``pendulum/torque_cmd`` and ``floor3/force_cmd`` (the one answering the previous
stamp, ``actuators.delay_periods`` stamps before that) while the simulator's last report showed it
applying the commands, else that report held (``SampleAssembly._control`` in
:mod:`stillframe.loop.assembly`). In lock-step a stamp of a scene driving the floor-3 force waits
for its ``floor3/load_cell`` reading too. The actuator the scene's controller does not drive is
taken as zero (the sim refuses its commands), whatever arrives on its topics.

- ``mode: lockstep``: a stamp is used once all its channels arrived and the command stamped
  t_k−1 did (the previous step's answer), as long as that takes: no wall time enters a
  lock-step run (the simulator publishes the next stamp only once this one is answered). Only
  when a newer stamp arrives first (a restarted simulator) on the topic of each channel it lacks
  is it used with what arrived (a partial update).
- ``mode: realtime``: a stamp is used when complete, when each channel it lacks has brought a
  newer stamp, or ``partial_after_s`` after its first message, with what arrived. A channel
  that comes later, within ``refilter_periods`` of the last stamp used, is taken into its stamp
  and the filter steps again from there (``late_inputs``, ``refilters``): the estimates already
  published stay, the next ones carry it. Not with ``adaptation.enabled`` (the adaptation has
  taken those samples) nor past the filter's start or a new design.

Parameters settable at run time (Kalman filters and EKF; refused with a reason, and the loop goes
on, when the value is wrong): ``process_noise_std`` (8 finite values ≥ 0) and
``measurement_noise_std`` (4 finite values > 0), the filter's W0 and V0 (thesis eq. 5.221–5.222),
starting at the scene's ``estimator`` values; what depends on them (Q, R, and for ``kf`` the
stationary covariance and gain) is recomputed before the next sample. Every other parameter is
read-only.

An estimator started while the loop runs (its first sample stamped after 0, e.g. restarted after
a crash) starts a Kalman filter from that sample's measurements rather than the scene's initial
state (:meth:`stillframe.estimation.kalman.LinearFilter.initialise_from`: its estimate at that
sample, with the covariance the measurements and ``estimator.restart_velocity_std`` give), at the
first sample that carries all four measurements (earlier ones are skipped and counted).

The design (``design`` parameter, filters only): ``scene`` or a model file, optionally ``@T``;
checked when set (:class:`stillframe.loop.designs.DesignSwitch`: refused with the reason, the
running filter kept) and taken at the first sample stamped at or after T: the new filter goes on
from the old one's estimate (:meth:`stillframe.estimation.base.Filter.continue_from`).

With ``adaptation.enabled`` the node runs the scene's
:class:`stillframe.loop.adaptation.Adaptation` on every sample it uses, after the filter's step,
as the one-process loop does. Each event is published on ``adaptation/events`` and counted in
``/diagnostics``; a design is written as a model file into ``adaptation_dir`` and handed over
at its sample through the ``design`` parameter of controller_node (``set_parameters``, waited
for: the controller holds it before any estimate of that sample exists) and of this node; a
design the controller refuses (or no answer within ``design_timeout_s``) is refused here too,
and the running one stays.

Every input is taken from the loop's own writer per topic
(:class:`stillframe.loop.writer_gate.WriterGate`): with the run's token (``run_token``), the
samples that carry it; without one, the sensors (and ``state_truth``) from the node the
``sensor_writer`` parameter names, the commands from ``command_writer``'s ("": the first writer
seen). Other writers' samples are refused before they are decoded, counted per topic and reason
and named in ``/diagnostics``.

Negative stamps are rejected and counted (``negative_stamps``). Messages not newer than the last
stamp used (``stale_messages``) or more than a second after it (``future_stamps``) are counted
and held apart; if every input of such a stamp arrives, the loop's time jumped (a simulator
restarted at t = 0, counted in ``time_jumps``) and the estimator starts again as above
(:mod:`stillframe.loop.assembly`). NaN or Inf readings are dropped by the filter and counted
(``non_finite``). With no input for ``stale_input_s``
(:class:`stillframe.node_runtime.support.LoopParameters`) after one came (simulator gone)
``/diagnostics`` says ERROR; the node idles.
"""

from __future__ import annotations

import functools
import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract import messages, topics
from stillframe.contract.adaptation_events import event_message
from stillframe.contract.codecs import (
    COMMAND_TOPICS,
    SENSOR_TOPICS,
    EstimateMessages,
    SampleGrid,
    TopicReader,
    command_reader,
    sensor_reader,
    state_reader,
    wrench_reader,
)
from stillframe.contract.signals import actuator_of
from stillframe.design.identified import write_mkr_file
from stillframe.durations import Durations
from stillframe.errors import InputError
from stillframe.estimation.base import Filter
from stillframe.estimation.factory import FILTERS, make_estimator
from stillframe.estimation.kalman import LinearFilter
from stillframe.files import write_text
from stillframe.loop import fast_inputs
from stillframe.loop.assembly import Ready, SampleAssembly
from stillframe.loop.designs import DesignSwitch, Handover, check_adaptation
from stillframe.loop.refilter import StepHistory
from stillframe.loop.wiring import command_topic, design_model, estimator_inputs
from stillframe.middleware import api
from stillframe.middleware.param_messages import value_msg
from stillframe.middleware.params import Parameter, SetParametersResult
from stillframe.middleware.taps import TappedPublisher
from stillframe.node_runtime import base
from stillframe.node_runtime.declarations import (
    CONTROLLER,
    AdaptationParameterValues,
    DesignParameterValues,
    EstimatorParameterValues,
    NoiseParameterValues,
)
from stillframe.node_runtime.parameters import NodeParameters
from stillframe.node_runtime.support import (
    ERROR,
    OK,
    WARN,
    LoopParameters,
    RateMeter,
    has_publisher,
    reaches_peer,
    wait_for_peers,
)

if TYPE_CHECKING:
    from stillframe.loop.adaptation import Adaptation


class EstimatorNode(base.LoopNode):
    """The estimator, its subscriptions, and the per-stamp assembly of samples."""

    NAME = "estimator_node"
    WRITER_PINS = ("command_writer", "sensor_writer")
    MANAGED = True

    def __init__(self, node: api.Node, params: LoopParameters,
                 values: dict[type, NodeParameters] | None = None) -> None:
        super().__init__(node, params, values)
        scene = params.scene
        self.estimator = make_estimator(scene, design_model(scene))
        self.inputs = estimator_inputs(scene)
        self.active = actuator_of(scene)
        partial_after_s = self.setting(EstimatorParameterValues).partial_after_s
        # lock-step waits for the whole sample, as long as it takes: no wall time enters it
        wait_ns = None if params.lockstep else round(partial_after_s * 1e9)
        # a late input re-runs a filter's last steps; an adaptation has already taken them
        revisable = (0 if params.lockstep or scene.adaptation.enabled
                     or not isinstance(self.estimator, Filter)
                     else self.setting(EstimatorParameterValues).refilter_periods)
        self.assembly = SampleAssembly(self.inputs, self.active, SampleGrid(params.period),
                                       wait_ns, params.lockstep, scene.actuators.delay_periods,
                                       revisable=revisable)
        self.history = StepHistory(revisable)
        spec, cov = topics.STATE_ESTIMATE, topics.STATE_COVARIANCE
        self.state_pub = TappedPublisher(node, spec.type_name, spec.name, spec.qos)
        self.cov_pub = TappedPublisher(node, cov.type_name, cov.name, cov.qos)
        self.out = EstimateMessages(params.run_token)
        for i, spec in enumerate(COMMAND_TOPICS):
            fast_inputs.subscribe(node, spec.type_name, spec.name, params.reader_qos(spec),
                                  command_reader(i, params.run_token),
                                  functools.partial(self.on_command, i),
                                  self.gates.add(spec.name, "command_writer"))
        self.counts = {"estimates": 0, "initialised_from_measurements": 0,
                       "skipped_before_initialisation": 0, "held_while_inactive": 0,
                       "refilters": 0}
        self.compute = Durations()
        self.rate = RateMeter()
        self.input_at: float | None = None   # when the last sample input arrived
        noise = (self.setting(NoiseParameterValues) if NoiseParameterValues
                 in self.declarations(scene) else None)
        self.noise = {} if noise is None else {
            "process_noise_std": noise.process_noise_std,
            "measurement_noise_std": noise.measurement_noise_std}
        if self.noise:
            self.set_noise(self.noise)
        self.designs = (DesignSwitch(scene, lambda built: built[0])
                        if DesignParameterValues in self.declarations(scene) else None)
        check_adaptation(scene, mode=params.mode)
        self.adaptation: Adaptation | None = None
        if scene.adaptation.enabled:
            # imported here, at configure, only by a node that adapts: the adaptation brings
            # identification, a second of start-up every other estimator does without
            from stillframe.loop.adaptation import Adaptation

            self.adaptation = Adaptation(scene, round(scene.duration / params.period))
        self.grid = SampleGrid(params.period)
        if self.adaptation is not None:
            settings = self.setting(AdaptationParameterValues)
            self.design_dir = Path(settings.adaptation_dir or tempfile.mkdtemp(
                prefix="stillframe-designs-"))
            self.design_dir.mkdir(parents=True, exist_ok=True)
            self.record_file = (Path(settings.adaptation_record)
                                if settings.adaptation_record else None)
            self.design_timeout_s = settings.design_timeout_s
            spec = topics.ADAPTATION_EVENTS
            self.events_pub = node.create_publisher(spec.type_name, spec.name, spec.qos)
            self.published = 0

    # -- parameters ----------------------------------------------------------------------
    @classmethod
    def declarations(cls, scene: Scene) -> tuple[type[NodeParameters], ...]:
        """The noise and design parameters only for the filters (not ``truth``)."""
        return tuple(c for c in super().declarations(scene)
                     if c not in (NoiseParameterValues, DesignParameterValues)
                     or scene.estimator.type in FILTERS)

    def set_noise(self, noise: dict[str, list[float]]) -> None:
        """Redesign the filter with ``noise``; InputError when it cannot be designed."""
        if isinstance(self.estimator, Filter):
            self.estimator.set_noise(noise["process_noise_std"], noise["measurement_noise_std"])

    def apply(self, parameters: list[Parameter]) -> SetParametersResult:
        """A new ``design`` (taken at its sample) or new noise settings (checked by their
        declarations): the filter redesigned with them (all or nothing)."""
        for p in parameters:
            if p.name == "design" and self.designs is not None:
                reason = self.designs.set(p.value, self.assembly.last_ns, self.node.get_logger())
                if reason is not None:
                    return SetParametersResult(False, reason)
        noisy = [p for p in parameters if p.name in self.noise]
        if not noisy:
            return SetParametersResult(True)
        noise = {**self.noise, **{p.name: list(p.value) for p in noisy}}
        try:
            self.set_noise(noise)
        except InputError as exc:
            return SetParametersResult(False, str(exc))
        self.noise = noise
        return SetParametersResult(True)

    def reset(self) -> None:
        """A new filter from the scene (``cleanup``, or the loop's time jumped), its counters
        and noise settings kept."""
        counters = self.estimator.counters
        self.estimator = make_estimator(self.params.scene, design_model(self.params.scene))
        self.estimator.counters = counters
        self.history.clear()
        if self.noise:
            self.set_noise(self.noise)

    # -- inputs --------------------------------------------------------------------------
    def subscribe_inputs(self) -> None:
        """The scene's estimator inputs (:func:`stillframe.loop.wiring.estimator_inputs`)."""
        sensors, token = self.params.scene.sensors, self.params.run_token
        handlers: dict[str, tuple[TopicReader, Callable[..., None]]] = {
            topics.FLOOR3_LOAD_CELL.name: (wrench_reader("floor3", "wrench.force.x", token),
                                           self.on_applied_force),
            topics.STATE_TRUTH.name: (state_reader(token), self.on_truth),
            **{spec.name: (sensor_reader(channel, sensors, token),
                           functools.partial(self.on_sensor, channel))
               for channel, spec in enumerate(SENSOR_TOPICS)},
        }
        for spec in self.inputs:
            fast_inputs.subscribe(self.node, spec.type_name, spec.name,
                                  self.params.reader_qos(spec),
                                  *handlers[spec.name], self.gates.add(spec.name, "sensor_writer"))

    def on_sensor(self, channel: int, ns: int, value: float, torque: float) -> None:
        """A reading of sensor ``channel`` stamped ``ns``, with the torque its message carries, into
        the sample assembly (the input's age restarts)."""
        self.input_at = time.monotonic()
        self.assembly.reading(channel, ns, value, time.monotonic_ns(), torque)

    def on_applied_force(self, ns: int, force: float) -> None:
        """The excitation force [N] stamped ``ns`` (the load cell) into the sample assembly."""
        self.assembly.applied_force(ns, force, time.monotonic_ns())

    def on_truth(self, ns: int, physical: np.ndarray) -> None:
        """The simulator's true physical state stamped ``ns`` into the sample assembly."""
        self.assembly.truth(ns, physical, time.monotonic_ns())

    def on_command(self, actuator: int, ns: int, value: float) -> None:
        """The command ``value`` of ``actuator`` stamped ``ns`` into the sample assembly (the input
        the filter's prediction uses)."""
        self.assembly.command_received(actuator, ns, value)

    # -- stepping ------------------------------------------------------------------------
    def process_ready(self) -> int:
        """Use every pending stamp that is ready, oldest first; how many were used."""
        if self.assembly.take_jump():        # a new run of the loop: a new filter
            self.reset()
        if (revised := self.assembly.take_revision()) and self.history.refilter(
                self.estimator, revised):
            self.counts["refilters"] += 1
        used = 0
        while (ready := self.assembly.pop_ready(now := time.monotonic_ns())) is not None:
            self.use(ready, now)
            used += 1
        return used

    def use(self, ready: Ready, now_ns: int) -> None:
        """Step the filter with the stamp taken at ``now_ns`` and publish the estimate."""
        started = time.perf_counter()
        timing, slot = self.timing, self.slot
        timing.begin(ready.ns)
        timing.mark_at(slot["first_in"], ready.first_ns)
        timing.mark_at(slot["ready"], now_ns)
        self.sample_start_ns = ready.first_ns
        sample, control = ready.sample, ready.control
        joined = False
        if (self.assembly.last_ns < 0 and ready.ns > 0
                and isinstance(self.estimator, LinearFilter)):
            # joined a running loop (restarted): start from the measurements, not the scene,
            # at the first sample that carries all of them
            if not (sample.present[:4].all() and np.isfinite(sample.measurements).all()):
                self.counts["skipped_before_initialisation"] += 1
                return
            self.estimator.initialise_from(sample, control)
            joined = True
            self.history.clear()        # no stepping back past the filter's start
            self.counts["initialised_from_measurements"] += 1
            self.node.get_logger().info(
                f"joined a running loop: started from the measurements at t = {sample.t:.9g} s")
        if self.designs is not None and (due := self.designs.due(ready.ns)) is not None:
            new = due[1]
            assert isinstance(self.estimator, Filter)
            new.continue_from(self.estimator)
            self.estimator = new
            self.history.clear()        # no stepping back past a new design
            self.node.get_logger().info(f"design {self.designs.current!r} taken at "
                                        f"t = {sample.t:.6g} s")
        # a filter started from this sample has used it
        estimate = (self.estimator.estimate() if joined
                    else self.history.step(self.estimator, ready))
        timing.mark(slot["computed"])
        self.assembly.used(ready.ns)
        if self.adaptation is not None:
            handover = self.adaptation.observe(self.grid.index(ready.ns), sample, control)
            if handover is not None:
                self.hand_over(handover)
            self.publish_events(ready.ns)
        if estimate is None:
            return
        if not self.activated:      # inactive: the filter kept current, nothing published
            self.counts["held_while_inactive"] += 1
            return
        state, cov = self.out.cdr(estimate, ready.ns)
        timing.mark(slot["serialized"])
        self.state_pub.publish(state)
        self.cov_pub.publish(cov)
        timing.mark(slot["written"])
        self.compute.add(time.perf_counter() - started)
        self.counts["estimates"] += 1
        self.rate.tick()

    def mid_sample(self) -> bool:
        """A stamp has some of its messages in, the first less than a period ago."""
        first = min((p.first_ns for p in self.assembly.pending.values()), default=None)
        return first is not None and time.monotonic_ns() - first < self.params.period * 1e9
    # -- adaptation ----------------------------------------------------------------------
    def hand_over(self, handover: Handover) -> None:
        """Write the design's model file and set it, due at its sample, on controller_node
        (waiting for the answer) and then on this node; refused by either: recorded, the
        running design kept."""
        path = self.design_dir / f"design_{handover.record['design']}.yaml"
        write_mkr_file(path, handover.structure, handover.structure.name)
        value = f"{path}@{handover.t!r}"
        reason = self.set_controller_design(value)
        if reason is None:
            try:
                assert self.designs is not None
                self.designs.request(value, self.assembly.last_ns)
            except InputError as exc:
                reason = f"estimator_node refused it: {exc}"
        if reason is not None:
            self.adaptation.events.append({"kind": "refusal", "t": handover.record["t"],
                                           "window_s": handover.record["window_s"],
                                           "reason": reason})
            self.node.get_logger().error(f"adaptation: design {path} not handed over: {reason}")
            return
        handover.record["file"] = str(path)
        self.node.get_logger().info(f"adaptation: design {path} handed over from "
                                    f"t = {handover.t:.6g} s")

    def set_controller_design(self, value: str) -> str | None:
        """``design`` := ``value`` on the controller (SetParameters, waited for); None when it
        took it, else why not."""
        controller = self.gates.pins["command_writer"] or CONTROLLER
        request = messages.new("rcl_interfaces/srv/SetParameters_Request", parameters=[
            messages.new("rcl_interfaces/msg/Parameter", name="design",
                         value=value_msg(value))])
        response = self.node.call_service(
            "rcl_interfaces/srv/SetParameters",
            f"{self.node.get_namespace().rstrip('/')}/{controller}/set_parameters", request,
            self.design_timeout_s)
        if response is None:
            return f"{controller} did not answer within {self.design_timeout_s:g} s"
        result = response.results[0]
        return None if result.successful else f"{controller} refused it: {result.reason}"

    def publish_events(self, ns: int) -> None:
        """The adaptation's new events on ``adaptation/events`` (stamped with the sample that
        decided them), and its record written."""
        assert self.adaptation is not None
        events = self.adaptation.events
        if self.published == len(events):
            return
        for record in events[self.published:]:
            self.events_pub.publish(event_message(ns, self.NAME, record))
        self.published = len(events)
        self.write_record()

    def write_record(self) -> None:
        """Write the adaptation's record (:meth:`~stillframe.loop.adaptation.Adaptation.report`) as
        one JSON document to the record file; nothing without an adaptation or a file."""
        if self.adaptation is not None and self.record_file is not None:
            write_text(self.record_file, json.dumps(self.adaptation.report()) + "\n",
                       what="adaptation record")

    def finish(self) -> None:
        """The adaptation's record written a last time, then the base's last status and phase
        log."""
        self.write_record()
        super().finish()

    def next_wait(self) -> float:
        """The longest wait of the next spin [s]: until the assembly's oldest partial sample times
        out, at most 0.1 s."""
        left = self.assembly.wait_ns_left(time.monotonic_ns())
        return 0.1 if left is None else min(0.1, left * 1e-9)

    def status(self) -> tuple[dict[str, Any], int, str]:
        """``/diagnostics``: the update rate, the assembly's and the filter's counts, the writer
        gates, the compute time percentiles [ms], the input's age [s], the design and the
        adaptation's counts; ERROR when no sample came for ``stale_input_s``, WARN on rejected
        inputs, refused writers or designs, or partial updates."""
        c, a = self.estimator.counters, self.assembly
        values = {"mode": self.params.mode, "rate_hz": self.rate.read(), **self.counts,
                  **a.counts, "updates": c.updates, "stale": c.stale,
                  "non_finite": c.non_finite, "missing": c.missing,
                  "rejected": c.rejected + a.counts["stale_messages"]
                  + a.counts["negative_stamps"] + a.counts["future_stamps"],
                  "refused_writers": self.gates.refused(), **self.gates.values(),
                  **{f"compute_ms_{k}": v for k, v in self.compute.recent().items()}}
        idle_s = 0.0 if self.input_at is None else time.monotonic() - self.input_at
        values["input_age_s"] = idle_s
        if self.designs is not None:
            values.update(design=self.designs.current, designs_taken=self.designs.taken)
        adaptation = ""
        if self.adaptation is not None:
            kinds = [e["kind"] for e in self.adaptation.events]
            values.update(adaptation_updates=len(self.adaptation.updates),
                          detections=kinds.count("detection"), designs=kinds.count("design"),
                          refused_designs=kinds.count("refusal"))
            if kinds:
                last = self.adaptation.events[-1]
                adaptation = f"adaptation: {last['kind']} at t = {last['t']:.6g} s"
        level = WARN if (values["rejected"] or values["refused_writers"]
                         or a.counts["partial_updates"]
                         or values.get("refused_designs")) else OK
        stale = ""
        if idle_s > self.params.stale_input_s:
            level, stale = ERROR, (f"stale input: no sample for {idle_s:.3g} s "
                                   "(simulator stale or gone)")
        return values, level, "; ".join(m for m in (stale, self.gates.message(), adaptation)
                                         if m)

    def status_stamp(self) -> int:
        """The stamp of the status [ns]: the newest sample assembled (0 before the first)."""
        return max(self.assembly.last_ns, 0)

    def peers_ready(self) -> bool:
        """The controller reads the estimates and publishes the scene's command topic."""
        controller = self.gates.pins["command_writer"] or CONTROLLER
        return reaches_peer(self.node, self.state_pub, controller) and has_publisher(
            self.node, command_topic(self.params.scene).name, controller)

    def start(self) -> None:
        """Wait for the controller in lock-step, then take the inputs."""
        if self.params.lockstep and self.active is not None:
            self.node.get_logger().info("lock-step: waiting for the controller")
            wait_for_peers(self.node, self.peers_ready)
        self.subscribe_inputs()


def build(node: api.Node) -> EstimatorNode:
    """The estimator on ``node`` from its parameters (InputError naming a wrong one)."""
    return EstimatorNode.build(node)


@api.node_main
def main() -> int:
    """Run the node (console script ``estimator_node``); bad parameters exit 2 with one line."""
    return base.main(EstimatorNode)


if __name__ == "__main__":
    sys.exit(main())
