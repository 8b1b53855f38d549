"""sim_node: the simulated rig on the topic contract (docs/architecture.md, docs/nodes.md).

A thin shell around :class:`stillframe.plant.frame_plant.Plant`. Per sample k it publishes
``/clock`` = t_k,
the three floor IMUs, the encoder (its ``effort`` the torque applied over the last period), the
load cell, the floor-3 actuator's load cell (the force applied) and ``state_truth``, all stamped
t_k, then waits for the command stamped t_k on the scene's actuator topic and advances the plant
with it:

- ``mode: lockstep``: waits as long as it takes, at most ``lockstep_timeout_s`` of wall time;
  after that it counts a lock-step timeout and holds the previous command. Once its peers have
  matched, sample 0 is awaited up to ``discovery_timeout_s``: its round trip ends the start-up
  (:meth:`stillframe.loop.pacing.Pacer.deadline_ns`).
- ``mode: realtime``: sample k is due at k·period of wall time after the start; a command not
  in by the next sample's due time is a deadline miss (previous command held), and a sample
  that starts more than a period late is an overrun.

At sensor rates of 100 Hz and more it also publishes each sample topic's decimated tap
(``/_decimated<topic>``, hidden: anti-alias filtered and thinned to 50 Hz or more,
:mod:`stillframe.loop.decimated_taps`) once the sample's command is taken, for the modal tracker.

With ``actuators.delay_periods`` = d ≥ 1 the command stamped t_k is applied from t_k+d on
(:class:`stillframe.plant.actuation_delay.ActuationDelay`): in real time the sim does not wait
for it, and a command not in when its period starts is the deadline miss; the safe state below
counts its periods from t_k+d.

Commands pass a :class:`stillframe.loop.command_gate.CommandGate` per topic: only one node's
writers (by their writer GIDs; the first seen, or the node named by the ``command_writer``
parameter) may command,
a second writer is reported in ``/diagnostics`` and ignored, and non-finite values, values beyond
the actuator's limit and stamps from the future or before the held command are rejected and
counted by reason.

When the newest command taken is ``command_timeout_periods`` (default 3) sample periods old, the
sim applies zero actuation (the safe state) until a fresh command comes, and counts the samples
(``safe_state_samples``). In real time it also applies zero while more than
``command_miss_limit`` (default 0.25; 0: never) of the last second's samples missed their
command, until no more than half that does (:class:`stillframe.loop.watchdog.MissRateGuard`;
``degraded_samples``, ``/diagnostics`` ERROR): a network that loses or delays that many commands
makes the held ones drive the structure instead of damping it.

At the end of the scene's duration it writes ``result_file`` (the evaluation of
:func:`stillframe.loop.closed_loop.evaluate` on its own truth history plus the loop's counters) and
an ``.npz`` of the histories beside it, then exits 0.
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
from stillframe.contract.codecs import (
    COMMAND_TOPICS,
    SAMPLE_TOPICS,
    SampleGrid,
    SensorMessages,
    command_reader,
)
from stillframe.contract.signals import Sample, actuator_of
from stillframe.files import open_output, write_text
from stillframe.loop.closed_loop import LoopHistory, evaluate, plant_report
from stillframe.loop.command_gate import CommandGate
from stillframe.loop.decimated_taps import DecimatedTaps
from stillframe.loop.energy_balance import EnergyTopic
from stillframe.loop.pacing import Pacer, wait_until
from stillframe.loop.watchdog import MissRateGuard, command_expired
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
    Durations,
    LoopParameters,
    hears_peer,
    reaches_peer,
    wait_for_peers,
)
from stillframe.plant.actuation_delay import ActuationDelay
from stillframe.plant.frame_plant import make_plant


class SimNode(base.LoopNode):
    """The plant, its publishers and the command subscriptions of one node.

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
        self.command_timeout_periods = settings.command_timeout_periods
        self.await_recorder = [t for t in settings.await_recorder if t]
        self.discovery_timeout_s = settings.discovery_timeout_s
        self.result_file = settings.result_file
        scene = params.scene
        self.plant = make_plant(scene)
        self.plant.warm_up()                # its kernels now, not in the first sample
        self.grid = SampleGrid(self.plant.period)
        self.active = actuator_of(scene)
        self.clock = ClockPublisher(node)
        # by topic, in the order of SensorMessages.fill and then the truth
        self.publishers = {s.name: TappedPublisher(node, s.type_name, s.name, params.qos(s))
                           for s in (*SAMPLE_TOPICS, topics.STATE_TRUTH)}
        self.messages = SensorMessages(scene.sensors)
        #: the sample topics anti-alias filtered and thinned (None at low rates): the tracker's
        self.taps = DecimatedTaps.of(node, SensorMessages(scene.sensors), scene.sensors.rate_hz,
                                     params.qos)
        #: pH plant: energy_balance and the live passivity check (None for the other plants)
        self.energy = EnergyTopic.of(node, self.plant, scene, params.qos(topics.ENERGY_BALANCE))
        limits = (scene.actuators.torque_limit, scene.actuators.force_limit)
        self.inputs = self.gates
        self.gates = [CommandGate(limit, self.inputs.add(spec.name, "command_writer"),
                                  active=i == self.active)
                      for i, (limit, spec) in enumerate(zip(limits, COMMAND_TOPICS, strict=True))]
        self.readers = [command_reader(i) for i in range(len(COMMAND_TOPICS))]
        self.subscriptions = [
            node.create_subscription(spec.type_name, spec.name,
                                     functools.partial(self.on_command, i),
                                     params.reader_qos(spec), raw=True)
            for i, spec in enumerate(COMMAND_TOPICS)]
        self.command = np.zeros(2)          # [torque, force] held
        self.command_ns = [-1, -1]
        self.delay = ActuationDelay(scene.actuators.delay_periods)
        self.now_ns = 0
        #: sample stamp -> when it was published, for the samples a command may still answer
        self.published_at: dict[int, float] = {}
        self.latency = Durations()
        self.commands_in_time = 0   # commands for the current sample taken before its deadline
        self.pacer = Pacer(self.grid.ns(self.plant.period), params.lockstep,
                           round(params.lockstep_timeout_s * 1e9))
        self.counts = {"rejected_commands": 0, "safe_state_samples": 0, "degraded_samples": 0}
        self.guard = MissRateGuard(max(10, round(1.0 / self.plant.period)),
                                   settings.command_miss_limit)
        self.k = 0
        self.pacer.start(time.monotonic_ns())   # again when the first sample is due
        #: handles messages for at most the given seconds while the sim waits: the node's
        #: ``spin_once``, or the composed process's (``container_node``)
        self.spin: Callable[[float], None] = node.spin_once   # type: ignore[method-assign]

    def on_command(self, actuator: int, cdr: bytes, info: api.MessageInfo) -> None:
        """Take a command its topic's gate lets through (module docstring); count the others."""
        gate = self.gates[actuator]
        if not gate.admits(info.publisher_gid, info.publication_sequence):
            self.counts["rejected_commands"] += 1
            return
        read = self.readers[actuator].read(cdr)
        if read is None:
            api.MALFORMED[COMMAND_TOPICS[actuator].name] += 1
            return
        ns, value = read
        if not gate.check(value, ns, self.now_ns, self.command_ns[actuator]):
            self.counts["rejected_commands"] += 1
            return
        if (actuator == self.active and ns in self.published_at
                and self.command_ns[actuator] != ns):
            self.latency.add(time.monotonic() - self.published_at[ns])
            # in time: taken before the advance that applies it (d = 0: in its own period)
            self.commands_in_time += ns >= self.now_ns - max(self.delay.periods - 1, 0) * (
                self.pacer.period_ns)
        self.command[actuator], self.command_ns[actuator] = value, ns
        if actuator == self.active:
            self.delay.put(self.grid.index(ns), self.command)

    def peers_ready(self) -> bool:
        """The estimator reads every sensor (and the truth when it is the ``truth`` estimator),
        and the controller's command is heard: matched on both sides, with the peers named by the
        ``command_writer`` pin or their default names (not only the recorder or a tool)."""
        scene = self.params.scene
        command = command_topic(scene)
        controller = self.inputs.pins["command_writer"] or CONTROLLER
        return (all(reaches_peer(self.node, self.publishers[spec.name], ESTIMATOR)
                    for spec in estimator_inputs(scene))
                and (command is None or hears_peer(
                    self.node, self.subscriptions[self.active], controller))
                and self.recorder_ready())

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
        """/clock, then the samples serialized first and written in one burst (the readers
        wake once for all of them instead of competing with the serialization for the CPU)."""
        self.clock.publish(ns)
        cdrs = self.messages.cdr(sample, ns)
        for pub, cdr in zip(self.publishers.values(), cdrs, strict=True):
            pub.publish(cdr)
        if self.energy is not None:
            self.energy.publish(float(sample.truth[3]))
        self.published_at[ns] = time.monotonic()
        oldest = ns - self.delay.periods * self.pacer.period_ns
        for old in [t for t in self.published_at if t < oldest]:
            del self.published_at[old]

    def wait_command(self, deadline_ns: int) -> bool:
        """Spin until the command stamped now arrives (True), the monotonic ``deadline_ns`` or
        shutdown passes (False: a sample interrupted while it waits is not run)."""
        if self.active is None:
            self.spin(0.0)
            return True
        while self.command_ns[self.active] != self.now_ns:
            remaining = (deadline_ns - time.monotonic_ns()) * 1e-9
            if remaining <= 0 or not api.ok():
                return False
            self.spin(remaining)
        return True

    def degraded(self, missed: bool) -> bool:
        """Record whether this sample missed its command; True while the guard holds zero."""
        was = self.guard.tripped
        if self.guard.record(missed) != was:
            log = self.node.get_logger()
            if was:
                log.info("control path recovered: commands applied again")
            else:
                log.error(self.degraded_message())
        return self.guard.tripped

    def command_timed_out(self) -> bool:
        """The newest command taken is ``command_timeout_periods`` periods older than the
        sample whose command is due now (or none came for as long): the controller is gone or
        stuck."""
        period = self.pacer.period_ns
        return self.active is not None and command_expired(
            self.now_ns - self.delay.periods * period, self.command_ns[self.active],
            self.command_timeout_periods * period)

    def sleep_until(self, when_ns: int) -> None:
        wait_until(when_ns, time.monotonic_ns, self.spin, self.rt.spin_margin_ns,
                   api.ok)

    def status(self) -> tuple[dict[str, Any], int, str]:
        lat = self.latency.recent()
        elapsed = (time.monotonic_ns() - self.pacer.started_ns) * 1e-9
        values = {
            "mode": self.params.mode, "step": self.k, "sim_time_s": self.k * self.plant.period,
            "loop_rate_hz": self.k / max(elapsed, 1e-9),
            "realtime_factor": self.k * self.plant.period / max(elapsed, 1e-9),
            **{f"latency_ms_{key}": value for key, value in lat.items()},
            **self.pacer.counts, **self.counts,
            "max_lateness_ms": 1e-6 * self.pacer.max_lateness_ns,
            "saturated_commands": self.plant.actuators.limited,
        }
        for gate, spec in zip(self.gates, COMMAND_TOPICS, strict=True):
            prefix = spec.name.replace("/", "_")
            values.update({f"{prefix}_{key}": value for key, value in gate.report().items()})
        bad = sum(self.pacer.counts.values()) + sum(self.counts.values())
        if self.energy is not None:
            values.update(self.energy.values())
            bad += self.energy.check.violations
        passivity = self.energy.check.message() if self.energy is not None else ""
        message = "; ".join(m for m in (self.degraded_message(), self.inputs.message(),
                                        passivity) if m)
        return values, ERROR if self.guard.tripped else WARN if bad else OK, message

    def status_stamp(self) -> int:
        return self.now_ns

    def degraded_message(self) -> str:
        g = self.guard
        return (f"control path degraded: {g.misses} of the last {g.window} commands missed "
                "their deadline; applying zero actuation") if g.tripped else ""

    def step(self, k: int) -> np.ndarray | None:
        """Sample k: publish, wait for its command, advance. The row [t, truth (8), command
        (2), load cell], or None on shutdown."""
        plant, pacer = self.plant, self.pacer
        self.k = k
        if not pacer.lockstep:
            self.sleep_until(pacer.due_ns(k))
        pacer.begin(k, time.monotonic_ns())
        if not api.ok():
            return None
        sample = plant.sample()
        self.now_ns = self.grid.ns(sample.t)
        self.publish(sample, self.now_ns)
        missed = False
        published_ns = time.monotonic_ns()
        if (pacer.lockstep or not self.delay.periods) and not self.wait_command(
                pacer.deadline_ns(k, published_ns)):
            if not api.ok():
                return None
            if pacer.lockstep:
                self.node.get_logger().warning(
                    f"lock-step timeout: no command for sample {k} (t = {sample.t:g} s) within "
                    f"{self.params.lockstep_timeout_s:g} s; holding the previous one", once=True)
            pacer.missed()
            missed = True
        elif k == 0 and pacer.lockstep and (waited := (
                time.monotonic_ns() - published_ns) * 1e-9) > self.params.lockstep_timeout_s:
            self.node.get_logger().info(
                f"start-up: sample 0's command came after {waited:.3g} s (a sample sent before "
                "its reader matched comes when the writer repairs it); not a timeout")
        if self.delay.periods:
            control, late = self.delay.due(k)
            if late and not pacer.lockstep:
                pacer.missed()
                missed = True
        else:
            control = self.command.copy()
        degraded = not pacer.lockstep and self.active is not None and self.degraded(missed)
        if self.command_timed_out():
            control[self.active] = 0.0      # the safe state: no actuation
            self.counts["safe_state_samples"] += 1
        elif degraded:
            control[self.active] = 0.0
            self.counts["degraded_samples"] += 1
        plant.advance(control)
        if self.taps is not None:      # after the command is taken: off its path
            self.taps.publish(sample, self.now_ns)
        self.rt.idle()
        if self.inputs.announce(self.node.get_logger()) or self.diagnostics.due():
            self.publish_status()
        return np.concatenate([[sample.t], sample.truth, control, [sample.force]])

    def run(self) -> LoopHistory | None:
        """The scene's duration, lock-step or real-time. Interrupted (SIGINT, SIGTERM: a launch
        whose other node died), the samples run so far, ``"complete": false`` and no
        evaluation; None when interrupted before the first sample."""
        p, plant = self.params, self.plant
        log = self.node.get_logger()
        log.info(f"{p.mode}: waiting for the estimator and controller")
        if wait_for_peers(self.node, self.peers_ready, self.discovery_timeout_s):
            # sample 0's round trip ends the start-up (Pacer.deadline_ns)
            self.pacer.first_timeout_ns = round(self.discovery_timeout_s * 1e9)
        else:
            if not api.ok():
                return None
            log.warning(f"estimator/controller not matched after {self.discovery_timeout_s:g} s;"
                        " starting anyway")
        n = round(p.scene.duration / plant.period)
        rows = np.empty((n, 12))
        self.inputs.read_graph()
        self.pacer.start(time.monotonic_ns())
        wall = time.perf_counter()
        done = 0
        for k in range(n):
            row = self.step(k)
            if row is None:
                break
            rows[k] = row
            done = k + 1
        if done == 0:
            return None
        self.k, rows = done, rows[:done]
        if done == n:
            self.publish_status()
        fine_t, floors, velocities = plant.truth_history()
        history = LoopHistory(rows[:, 0], rows[:, 1:9], np.full((done, 8), np.nan),
                              rows[:, 9:11], rows[:, 11], fine_t, floors, velocities)
        if self.active is not None and done == n:
            history.evaluation = evaluate(history, p.scene)
        history.evaluation.update({
            "complete": done == n, "steps_planned": n,
            "mode": p.mode, "steps": done, "wall_s": time.perf_counter() - wall,
            "malformed_samples": sum(api.MALFORMED.values()),
            **self.pacer.counts, **self.counts, "latency_ms": self.latency.summary(),
            "commands_in_time": self.commands_in_time,
            "command_gates": {spec.name: gate.report()
                              for gate, spec in zip(self.gates, COMMAND_TOPICS, strict=True)},
            "max_lateness_ms": 1e-6 * self.pacer.max_lateness_ns,
            "plant": plant_report(plant),
        })
        if self.energy is not None:     # pH plant: the last balance and the passivity check
            history.evaluation["energy_balance"] = self.energy.values()
        return history


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
    ``"complete": false``, when interrupted after the first sample)."""
    history = sim.run()
    if history is not None and sim.result_file:
        write_result(history, Path(sim.result_file))


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
