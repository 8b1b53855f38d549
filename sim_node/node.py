"""sim_node: the simulated rig on the topic contract (docs/architecture.md, docs/nodes.md).

A thin shell around :class:`stillframe.loop.step.LoopStep`, the sample period that the
one-process loop runs too. Per sample k it publishes ``/clock`` = t_k, the three floor IMUs, the
encoder (its ``effort`` the torque applied over the last period), the load cell, the floor-3
actuator's load cell (the force applied) and ``state_truth``, all stamped t_k, then waits for the
command stamped t_k on the scene's actuator topic, offers it to the step (its command gate) and
advances the period. The sample topics no node of the loop reads (``state_truth`` unless the
``truth`` estimator reads it, the floor-3 load cell unless the force is driven) go out after the
advance, off the command's path:

- ``mode: lockstep``: the simulator never advances without the command of the current sample.
  It waits while the loop's peers (the estimator reading the samples, the controller writing
  the command) are on the graph; when one has left the graph, or no command came within
  ``lockstep_timeout_s`` (a long guard against a peer that is alive but stuck), the run ends:
  one line naming the peer and the sample, the partial result (``"complete": false``) and exit
  code 7 (:class:`stillframe.errors.LoopError`).
- ``mode: realtime``: sample k is due at k·period of wall time after the start; a command not
  in by the next sample's due time is a deadline miss (previous command held), and a sample
  that starts more than a period late is an overrun.

At sensor rates of 100 Hz and more it also publishes each sample topic's decimated tap
(``/_decimated<topic>``, hidden: anti-alias filtered and thinned to 50 Hz or more,
:mod:`stillframe.loop.decimated_taps`) once the sample's command is taken, for the modal tracker.

With ``actuators.delay_periods`` = d ≥ 1 the command stamped t_k is applied from t_k+d on
(:class:`stillframe.plant.actuation_delay.ActuationDelay`): in real time the sim does not wait
for it, and a command not in when its period starts is the deadline miss.

Commands pass the step's :class:`stillframe.loop.command_gate.CommandGate` per topic: only
the loop's controller may command (with the run's token, the commands that carry it; without one,
one node's writers by their writer GIDs: the first seen, or the node named by the
``command_writer`` parameter), another writer is reported in ``/diagnostics`` and ignored, and
non-finite values, values beyond the command's bound and stamps from the future or before the
held command are rejected and counted by reason. The safe state (zero actuation once the newest
command is ``command_timeout_periods`` old) and, in real time, the miss-rate guard
(``command_miss_limit``) are the step's (:class:`stillframe.loop.step.LoopStep`).

At the end of the scene's duration it writes ``result_file`` (the evaluation of
:func:`stillframe.loop.evaluation.evaluate` on its own truth history plus the loop's counters)
and an ``.npz`` of the histories beside it, then exits 0. A plant that diverges ends the run the
same way, with the partial result and the integration error's line and code (4).

A scene's structure events (:mod:`stillframe.config.events`) are the step's too: at the sample
where one applies, the simulator publishes it on ``structure_events`` (stamped with the sample,
before the sample's readings) and logs it; the result lists them under ``structure_events``.
"""

from __future__ import annotations

import functools
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from stillframe.contract import topics
from stillframe.contract.codecs import COMMAND_TOPICS, SAMPLE_TOPICS, SensorMessages, command_reader
from stillframe.contract.signals import Sample
from stillframe.contract.structure_events import event_message, summary
from stillframe.durations import Durations
from stillframe.errors import IntegrationError, LoopError, StillframeError
from stillframe.files import open_output, write_text
from stillframe.loop.decimated_taps import DecimatedTaps
from stillframe.loop.energy_balance import EnergyTopic
from stillframe.loop.evaluation import LoopHistory, evaluate, plant_report
from stillframe.loop.pacing import Pacer, wait_until
from stillframe.loop.parts import simulator_of
from stillframe.loop.step import LoopStep
from stillframe.loop.wiring import command_topic, estimator_inputs
from stillframe.middleware import api
from stillframe.middleware.clock import ClockPublisher
from stillframe.middleware.names import is_hidden
from stillframe.middleware.taps import TappedPublisher
from stillframe.node_runtime import base
from stillframe.node_runtime.declarations import (
    CONTROLLER,
    ESTIMATOR,
    LOOP_NODES,
    SimParameterValues,
)
from stillframe.node_runtime.parameters import NodeParameters
from stillframe.node_runtime.support import (
    ERROR,
    OK,
    RECORDER_NODE,
    WARN,
    LoopParameters,
    has_publisher,
    has_subscriber,
    hears_peer,
    malformed_samples,
    reaches_peer,
    wait_for_peers,
)
from stillframe.plant.protocol import Plant

#: lock-step: how often [s] a sample still waiting for its command asks the graph whether the
#: loop's peers are still there
PEER_CHECK_S = 0.5


class SimNode(base.LoopNode):
    """The plant's sample periods (:class:`~stillframe.loop.step.LoopStep`) on the topics: the
    publishers, the command subscriptions, the pacing and the status.

    Not a managed node: it drives the loop's time (each sample waits for its command in
    lock-step), so an inactive simulator would stall the estimator and the controller rather
    than leave them idle; it starts the run when its peers are there and ends it (docs/nodes.md,
    lifecycle)."""

    NAME = "sim_node"
    WRITER_PINS = ("command_writer",)

    def __init__(self, node: api.Node, params: LoopParameters,
                 values: dict[type, NodeParameters] | None = None) -> None:
        super().__init__(node, params, values)
        settings = self.setting(SimParameterValues)
        self.await_recorder = [t for t in settings.await_recorder if t]
        self.await_status_reader = settings.await_status_reader
        self.discovery_timeout_s = settings.discovery_timeout_s
        self.result_file = settings.result_file
        scene = params.scene
        spec, plant = simulator_of(
            scene, mode=params.mode, lockstep_timeout_s=settings.lockstep_timeout_s,
            command_timeout_periods=settings.command_timeout_periods,
            command_miss_limit=settings.command_miss_limit)
        self.spec = spec
        plant.warm_up()                     # its kernels now, not in the first sample
        self.step = LoopStep(spec, plant, [self.gates.add(topic.name, "command_writer")
                                            for topic in COMMAND_TOPICS])
        self.clock = ClockPublisher(node)
        # by topic, in the order of SensorMessages.fill and then the truth
        self.publishers = {s.name: TappedPublisher(node, s.type_name, s.name, params.qos(s))
                           for s in (*SAMPLE_TOPICS, topics.STATE_TRUTH)}
        self.messages = SensorMessages(scene.sensors, params.run_token)
        #: the sample topics no node of the loop waits for (``state_truth`` unless the ``truth``
        #: estimator reads it, the floor-3 load cell unless the force is driven) go out after
        #: the advance, off the command's path: their indices in :attr:`publishers`, and the others'
        read = {t.name for t in estimator_inputs(scene)} | (
            {topics.EXCITATION_WRENCH.name} if command_topic(scene) is not None else set())
        names = list(self.publishers)
        self.on_path = [i for i, name in enumerate(names) if name in read]
        self.after_path = [i for i, name in enumerate(names) if name not in read]
        self.writers = list(self.publishers.values())
        self.cdrs: list[bytearray] = []
        #: the sample topics anti-alias filtered and thinned (None at low rates): the tracker's
        self.taps = DecimatedTaps.of(node, SensorMessages(scene.sensors, params.run_token),
                                     scene.sensors.rate_hz, params.qos)
        #: pH plant: energy_balance and the live passivity check (None for the other plants)
        self.energy = EnergyTopic.of(node, plant, scene, params.qos(topics.ENERGY_BALANCE))
        #: a scene with events: what the plant changed and when (None without events)
        self.structure_events = (node.create_publisher(
            topics.STRUCTURE_EVENTS.type_name, topics.STRUCTURE_EVENTS.name,
            params.qos(topics.STRUCTURE_EVENTS)) if spec.events else None)
        self.readers = [command_reader(i, params.run_token)
                        for i in range(len(COMMAND_TOPICS))]
        self.subscriptions = [
            node.create_subscription(topic.type_name, topic.name,
                                     functools.partial(self.on_command, i),
                                     params.reader_qos(topic), raw=True)
            for i, topic in enumerate(COMMAND_TOPICS)]
        #: sample stamp -> when it was published, for the samples a command may still answer
        self.published_at: dict[int, float] = {}
        self.latency = Durations()
        self.commands_in_time = 0   # commands for the current sample taken before its deadline
        self.pacer = Pacer(spec.period_ns, spec.lockstep)
        self.pacer.start(time.monotonic_ns())   # again when the first sample is due
        #: handles messages for at most the given seconds while the sim waits: the node's
        #: ``spin_once``, or the composed process's (``container_node``)
        self.spin: Callable[[float], None] = node.spin_once   # type: ignore[method-assign]

    @property
    def plant(self) -> Plant:
        """The plant the step advances (lumped, FE or port-Hamiltonian, as the scene's ``plant``
        section chose)."""
        return self.step.plant

    def on_command(self, actuator: int, cdr: bytes, info: api.MessageInfo) -> None:
        """Offer a command to the step (its writer, then its value and stamp); count the others."""
        step = self.step
        if not step.admits(actuator, info.publisher_gid, info.publication_sequence, cdr):
            return
        read = self.readers[actuator].read(cdr)
        if read is None:
            self.node.malformed[COMMAND_TOPICS[actuator].name] += 1
            return
        ns, value = read
        fresh = ns != step.command_ns[actuator]
        if not step.offer(actuator, value, ns):
            return
        if actuator == self.spec.active and ns == step.now_ns and fresh:
            self.timing.mark(self.slot["command_in"])
        if actuator == self.spec.active and ns in self.published_at and fresh:
            self.latency.add(time.monotonic() - self.published_at[ns])
            # in time: taken before the advance that applies it (d = 0: in its own period)
            self.commands_in_time += ns >= step.now_ns - max(self.spec.delay_periods - 1, 0) * (
                self.spec.period_ns)

    def peers_ready(self) -> bool:
        """The estimator reads every sensor (and the truth when it is the ``truth`` estimator),
        and the controller's command is heard: matched on both sides, with the peers named by the
        ``command_writer`` pin or their default names (not only the recorder or a tool); the
        recorder subscribed (``await_recorder``) and the status reader matched
        (``await_status_reader``: otherwise a short run across DDS vendors can end before the
        launch hears any status, and its report loses the nodes' last ones)."""
        scene = self.params.scene
        command = command_topic(scene)
        return (all(reaches_peer(self.node, self.publishers[spec.name], ESTIMATOR)
                    for spec in estimator_inputs(scene))
                and (command is None or hears_peer(
                    self.node, self.subscriptions[self.spec.active], self.controller_name))
                and self.recorder_ready()
                and (not self.await_status_reader or reaches_peer(
                    self.node, self.diagnostics.pub, self.await_status_reader)))

    @property
    def controller_name(self) -> str:
        """The node whose command is awaited: the ``command_writer`` pin, else the default."""
        return self.gates.pins["command_writer"] or CONTROLLER

    def peer_gone(self) -> str | None:
        """Lock-step: the loop's peer that has left the graph (the estimator, which reads the
        samples, or the controller, which writes the command), or None while both are there."""
        scene = self.params.scene
        command = command_topic(scene)
        if command is not None and not has_publisher(self.node, command.name,
                                                     self.controller_name):
            return self.controller_name
        inputs = estimator_inputs(scene)
        if inputs and not has_subscriber(self.node, inputs[0].name, ESTIMATOR):
            return ESTIMATOR
        return None

    def recorder_ready(self) -> bool:
        """Every topic of ``await_recorder`` that the loop's nodes publish is subscribed by the
        recorder (``*``: every such topic), so that a launch's bag misses no sample."""
        if not self.await_recorder:
            return True
        # "*": every topic the recorder takes, i.e. not the hidden ones (the monitor taps)
        wanted = ([t for t, _ in self.node.get_topic_names_and_types() if not is_hidden(t)]
                  if self.await_recorder == ["*"] else self.await_recorder)
        loop_nodes = {(topics.DEFAULT_NAMESPACE, n) for n in LOOP_NODES}
        return all(
            any(s.node_name == RECORDER_NODE for s in self.node.get_subscriptions_info_by_topic(t))
            for t in wanted
            if any((p.node_namespace, p.node_name) in loop_nodes
                   for p in self.node.get_publishers_info_by_topic(t))
        )

    def publish(self, sample: Sample, ns: int) -> None:
        """The samples serialized, then /clock and the samples written in one burst (the
        readers wake once for all of them instead of competing with the serialization for the
        CPU); of the sample topics only those a node of the loop reads (:attr:`on_path`)."""
        self.cdrs = cdrs = self.messages.cdr(sample, ns)
        self.timing.mark(self.slot["serialized"])
        self.clock.publish(ns)
        writers = self.writers
        for i in self.on_path:
            writers[i].publish(cdrs[i])
        if self.energy is not None:
            self.energy.publish(float(sample.truth[3]))
        self.timing.mark(self.slot["written"])
        self.published_at[ns] = time.monotonic()
        oldest = ns - self.spec.delay_periods * self.spec.period_ns
        for old in [t for t in self.published_at if t < oldest]:
            del self.published_at[old]

    def announce_structure(self) -> None:
        """The structure events the step applied at this sample: on ``structure_events``
        (stamped with the sample, before its readings) and in the log."""
        records = [event.record(self.spec.period) for event in self.step.changed]
        assert self.structure_events is not None
        self.structure_events.publish(
            event_message(self.step.now_ns, self.diagnostics.name, records))
        for record in records:
            self.node.get_logger().info(f"structure changed: {summary(record)}")

    def publish_after(self, sample: Sample, ns: int) -> None:
        """What no node of the loop waits for, once the command is taken: the sample topics
        off the command's path (:attr:`after_path`) and the decimated taps."""
        writers, cdrs = self.writers, self.cdrs
        for i in self.after_path:
            writers[i].publish(cdrs[i])
        if self.taps is not None:
            self.taps.publish(sample, ns)

    def await_command(self, k: int, t: float) -> bool:
        """Lock-step: spin until the step has the command of sample k (True), or shutdown
        (False). Every :data:`PEER_CHECK_S` of waiting the graph is asked whether the peers are
        still there: LoopError when one has left, or when ``lockstep_timeout_s`` has passed."""
        step = self.step
        started = time.monotonic()
        check = started + PEER_CHECK_S
        while not step.answered:
            if not api.ok():
                return False
            now = time.monotonic()
            if now >= check:
                check = now + PEER_CHECK_S
                if (gone := self.peer_gone()) is not None:
                    raise LoopError(f"lock-step: {gone} left the graph while sample {k} "
                                    f"(t = {t:g} s) awaited its command; the run ended there")
                if now - started >= self.spec.lockstep_timeout_s:
                    raise LoopError(
                        f"lock-step: no command for sample {k} (t = {t:g} s) within "
                        f"lockstep_timeout_s = {self.spec.lockstep_timeout_s:g} s, "
                        f"{self.controller_name} still on the graph; the run ended there")
            self.spin(min(PEER_CHECK_S, max(check - now, 0.0)))
        return True

    def await_deadline(self, deadline_ns: int) -> bool:
        """Real time: spin until the step has the command of this sample (True), the monotonic
        ``deadline_ns`` or shutdown passes (False)."""
        step = self.step
        while not step.answered:
            remaining = (deadline_ns - time.monotonic_ns()) * 1e-9
            if remaining <= 0 or not api.ok():
                return False
            self.spin(remaining)
        return True

    def slack_ns(self, now_ns: int) -> int | None:
        """Real time: how long before the next sample is due; None in lock-step."""
        return None if self.pacer.lockstep else self.pacer.due_ns(self.step.k) - now_ns

    def sleep_until(self, when_ns: int) -> None:
        """Wait until ``when_ns`` on the monotonic clock, handling messages meanwhile
        (:func:`~stillframe.loop.pacing.wait_until`: asleep in the spin, polling over its last
        ``rt.spin_margin_ns``); returns early on shutdown."""
        wait_until(when_ns, time.monotonic_ns, self.spin, self.rt.spin_margin_ns,
                   api.ok)

    def status(self) -> tuple[dict[str, Any], int, str]:
        """``/diagnostics``: the mode, step and simulated time, the loop rate and real-time factor,
        the command latency percentiles [ms], the pacer's and the step's counts, each command
        topic's writer gate, saturated commands and (with an energy ledger) the energy balance;
        ERROR when the miss-rate guard tripped, WARN when any count is non-zero."""
        step, lat = self.step, self.latency.recent()
        elapsed = (time.monotonic_ns() - self.pacer.started_ns) * 1e-9
        period = self.spec.period
        values = {
            "mode": self.params.mode, "step": step.k, "sim_time_s": step.k * period,
            "loop_rate_hz": step.k / max(elapsed, 1e-9),
            "realtime_factor": step.k * period / max(elapsed, 1e-9),
            **{f"latency_ms_{key}": value for key, value in lat.items()},
            **self.pacer.counts, **step.counts,
            "max_lateness_ms": 1e-6 * self.pacer.max_lateness_ns,
            "saturated_commands": self.plant.actuators.limited,
        }
        for name, report in step.gate_reports([t.name for t in COMMAND_TOPICS]).items():
            prefix = name.replace("/", "_")
            values.update({f"{prefix}_{key}": value for key, value in report.items()})
        bad = sum(self.pacer.counts.values()) + sum(step.counts.values())
        if self.energy is not None:
            values.update(self.energy.values())
            bad += self.energy.check.violations
        passivity = self.energy.check.message() if self.energy is not None else ""
        message = "; ".join(m for m in (self.degraded_message(), self.gates.message(),
                                        passivity) if m)
        return values, ERROR if step.guard.tripped else WARN if bad else OK, message

    def status_stamp(self) -> int:
        """The stamp of the status [ns]: the sample the step is at."""
        return self.step.now_ns

    def degraded_message(self) -> str:
        """One line when the miss-rate guard has tripped (how many of its window's commands missed
        and that zero actuation is applied), "" otherwise."""
        g = self.step.guard
        return (f"control path degraded: {g.misses} of the last {g.window} commands missed "
                "their deadline; applying zero actuation") if g.tripped else ""

    def sample_period(self, k: int) -> np.ndarray | None:
        """Sample k: publish, wait for its command, advance. The row [t, truth (8), command
        (2), load cell], or None on shutdown."""
        step, pacer, spec = self.step, self.pacer, self.spec
        timing, slot = self.timing, self.slot
        due = timing.ended_ns if pacer.lockstep else pacer.due_ns(k)
        if not pacer.lockstep:
            self.sleep_until(due)
        woke = time.monotonic_ns()
        pacer.begin(k, woke)
        if not api.ok():
            return None
        sample = step.sample()
        timing.begin(step.now_ns)
        timing.mark_at(slot["due"], due)
        timing.mark_at(slot["woke"], woke)
        timing.mark(slot["sampled"])
        if step.changed:
            self.announce_structure()
        self.publish(sample, step.now_ns)
        missed = False
        if spec.lockstep:
            if not self.await_command(k, sample.t):
                return None
        elif not spec.delay_periods and not self.await_deadline(pacer.due_ns(k + 1)):
            if not api.ok():
                return None
            missed = True
        timing.mark(slot["answered"])
        period = step.advance(missed=missed)
        timing.mark(slot["advanced"])
        if period.missed:
            pacer.missed()
        if period.guard_changed:
            log = self.node.get_logger()
            if step.guard.tripped:
                log.error(self.degraded_message())
            else:
                log.info("control path recovered: commands applied again")
        self.publish_after(sample, step.now_ns)
        timing.mark(slot["tapped"])
        self.idle()
        if self.status_due():
            self.publish_status()
        timing.end(slot["done"])
        return np.concatenate([[sample.t], sample.truth, period.command, [sample.force]])

    def run(self) -> tuple[LoopHistory | None, StillframeError | None]:
        """The scene's duration, lock-step or real-time, and the error that ended it early
        (a lock-step peer gone, a plant that diverged), if one did. Interrupted (SIGINT,
        SIGTERM: a launch whose other node died) or ended early, the samples run so far,
        ``"complete": false`` and no evaluation; None when no sample ran."""
        p, spec, plant = self.params, self.spec, self.plant
        log = self.node.get_logger()
        log.info(f"{p.mode}: waiting for the estimator and controller")
        if not wait_for_peers(self.node, self.peers_ready, self.discovery_timeout_s):
            if not api.ok():
                return None, None
            log.warning(f"estimator/controller not matched after {self.discovery_timeout_s:g} s;"
                        " starting anyway")
        n = spec.samples
        rows = np.empty((n, 12))
        self.gates.read_graph()
        self.pacer.start(time.monotonic_ns())
        self.timing.ended_ns = self.pacer.started_ns
        wall = time.perf_counter()
        done, error = 0, None
        for k in range(n):
            try:
                row = self.sample_period(k)
            except (LoopError, IntegrationError) as exc:
                error = exc
                break
            if row is None:
                break
            rows[k] = row
            done = k + 1
        self.write_phases()
        if done == 0:
            return None, error
        rows = rows[:done]
        if done == n:
            self.publish_status()
        fine_t, floors, velocities = plant.truth_history()
        history = LoopHistory(rows[:, 0], rows[:, 1:9], np.full((done, 8), np.nan),
                              rows[:, 9:11], rows[:, 11], fine_t, floors, velocities)
        if spec.active is not None and done == n:
            history.evaluation = evaluate(history, p.scene)
        history.evaluation.update({
            "complete": done == n, "steps_planned": n,
            "mode": p.mode, "steps": done, "wall_s": time.perf_counter() - wall,
            "malformed_samples": malformed_samples(self.node),
            **self.pacer.counts, **self.step.counts, "latency_ms": self.latency.summary(),
            "commands_in_time": self.commands_in_time,
            "command_gates": self.step.gate_reports([t.name for t in COMMAND_TOPICS]),
            "max_lateness_ms": 1e-6 * self.pacer.max_lateness_ns,
            "plant": plant_report(plant),
            "structure_events": self.step.event_records(),
            "realtime": {"applied": self.rt.applied, "refused": self.rt.refused},
        })
        if error is not None:
            history.evaluation["error"] = {"kind": type(error).__name__, "message": str(error)}
        if self.energy is not None:     # pH plant: the last balance and the passivity check
            history.evaluation["energy_balance"] = self.energy.values()
        return history, error


def write_result(history: LoopHistory, path: Path) -> None:
    """The evaluation as JSON at ``path`` and the histories as ``path`` with suffix ``.npz``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(history.evaluation, indent=2) + "\n", what="result file")
    with open_output(path.with_suffix(".npz"), what="history file") as stream:
        np.savez(stream, t=history.t, truth=history.truth, command=history.command,
                 force=history.force, fine_t=history.fine_t, fine_floors=history.fine_floors,
                 fine_velocities=history.fine_velocities)


def build(node: api.Node) -> SimNode:
    """The simulator on ``node`` from its parameters (InputError naming a wrong one), its
    real-time practices entered."""
    sim = SimNode.build(node)
    sim.enter_realtime()
    return sim


def run(sim: SimNode) -> None:
    """The scene, then its result in ``result_file`` (when given; a partial one, marked
    ``"complete": false``, when interrupted or ended early after the first sample); the error
    that ended it early is raised after the result is written."""
    history, error = sim.run()
    if history is not None and sim.result_file:
        write_result(history, Path(sim.result_file))
    if error is not None:
        raise error


@api.node_main
def main() -> int:
    """Run the node (console script ``sim_node``); bad parameters exit 2 with one line."""
    node = api.create_node("sim_node", namespace=topics.DEFAULT_NAMESPACE)
    try:
        run(build(node))
    finally:
        node.destroy_node()
    return 0


if __name__ == "__main__":
    sys.exit(main())
