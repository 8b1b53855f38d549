"""controller_node: the scene's controller on the topic contract (docs/nodes.md).

A thin shell around :func:`stillframe.control.factory.make_controller`. For every
``state_estimate`` stamped t_k it calls ``command(t_k, estimate, load cell at t_k)`` and
publishes the command stamped t_k on ``pendulum/torque_cmd`` (``torque.z``) or
``floor3/force_cmd`` (``force.x``). The load cell comes from ``excitation/wrench``: in
lock-step the controller waits for the reading stamped t_k, as long as it takes (no wall time
enters a lock-step run); in real time it uses the newest one.

Parameters settable at run time (``stillframe param set`` or ``ros2 param set``; refused with a
reason, and the loop goes on, when the value is wrong): ``enabled`` (bool; false: zero command
from the next sample on) and ``command_limit`` (the controller's limit ±limit [N m or N], finite
and ≥ 0, 0: none; starts at ``controller.limit``; every law takes it at its next sample, the MPC
and the anti-windup LQG plan with it), and ``design`` (``scene`` or a model file, optionally
``@T``: checked when set, refused with the reason and the running design kept when it fails,
else the law of the LQG designed on it taken from the estimate stamped at or after T:
:class:`stillframe.loop.designs.DesignSwitch`). Every other parameter is read-only.

Watchdog (``/diagnostics`` level ERROR while it holds the command at zero): once armed by a
first estimate, when the newest estimate is ``watchdog_periods`` periods older than the newest
sample time the node has seen (the load cell's stamp, which every sample carries, or ``/clock`` with
``use_sim_time`` if newer), the node publishes the supervisor's zero command stamped with that time,
once per sample time, and counts it. Sample time rather than wall time: in lock-step the simulator
then applies the zero command instead of timing out, and it needs no ``/clock``.

Inputs are taken from the loop's own writer per topic
(:class:`stillframe.loop.writer_gate.WriterGate`): with the run's token (``run_token``), the
samples that carry it; without one (and for ``/clock``, which has no header: read with
``use_sim_time`` by the node itself for its watchdog) ``state_estimate`` from the node
``estimate_writer`` names, the load cell and ``/clock`` from ``sensor_writer``'s ("": the first
writer seen). Other writers' samples are refused, counted per topic and reason and named in
``/diagnostics``.

When the loop's time goes back (a restarted simulator: an estimate stamped before the last one,
with a load-cell reading of that stamp; :mod:`stillframe.loop.matching`) the watchdog is disarmed
until the next estimate, and counted (``time_jumps``). With no load-cell reading for
``stale_input_s`` (:class:`stillframe.node_runtime.support.LoopParameters`) after one came
(simulator gone) ``/diagnostics`` says ERROR; the node idles.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np

from stillframe.contract import topics
from stillframe.contract.codecs import (
    COMMAND_TOPICS,
    CommandMessage,
    SampleGrid,
    clock_reader,
    estimate_reader,
    wrench_reader,
)
from stillframe.contract.signals import Command, Estimate
from stillframe.control.factory import make_controller
from stillframe.control.supervisor import RUNAWAY_FACTOR
from stillframe.design.coordinates import design_map
from stillframe.durations import Durations
from stillframe.loop import fast_inputs
from stillframe.loop.designs import DesignSwitch
from stillframe.loop.matching import ForceMatching
from stillframe.loop.watchdog import EstimateWatchdog
from stillframe.loop.wiring import design_model
from stillframe.middleware import api
from stillframe.middleware.params import Parameter, SetParametersResult
from stillframe.middleware.taps import TappedPublisher
from stillframe.node_runtime import base
from stillframe.node_runtime.declarations import SIM, ControllerParameterValues
from stillframe.node_runtime.parameters import NodeParameters
from stillframe.node_runtime.support import (
    ERROR,
    OK,
    WARN,
    LoopParameters,
    RateMeter,
    reaches_peer,
    wait_for_peers,
)


class ControllerNode(base.LoopNode):
    """The controller, its subscriptions and the command publisher."""

    NAME = "controller_node"
    WRITER_PINS = ("estimate_writer", "sensor_writer")
    MANAGED = True

    def __init__(self, node: api.Node, params: LoopParameters,
                 values: dict[type, NodeParameters] | None = None) -> None:
        super().__init__(node, params, values)
        scene = params.scene
        design = design_model(scene)
        self.controller = make_controller(scene, design)
        self.to_design = design_map(design)    # z = T · physical, built once
        self.grid = SampleGrid(params.period)
        spec = COMMAND_TOPICS[self.controller.actuator]
        self.pub = TappedPublisher(node, spec.type_name, spec.name, spec.qos)
        self.out = CommandMessage(self.controller.actuator, params.run_token)
        self.sim_time = bool(node.get_parameter("use_sim_time").value)
        self.clock_ns = 0                   # the newest /clock of the simulator (sim time)
        self.matching = ForceMatching(None, params.lockstep)
        self.watchdog = EstimateWatchdog(self.controller, self.grid)
        self.last_command = Command(0.0)
        self.input_at: float | None = None   # when the last load-cell reading arrived
        self.compute = Durations()
        self.rate = RateMeter()
        settings = self.setting(ControllerParameterValues)
        self.enabled = settings.enabled
        self.controller.set_limit(settings.command_limit)
        self.designs = DesignSwitch(scene, lambda built: built[1])

    def apply(self, parameters: list[Parameter]) -> SetParametersResult:
        """``enabled`` and ``command_limit`` (checked by their declarations) in effect from the
        next sample on."""
        for p in parameters:
            if p.name == "enabled":
                self.enabled = p.value
                self.controller.enabled = self.enabled and self.activated
            elif p.name == "command_limit":
                self.controller.set_limit(p.value)
            elif p.name == "design":
                reason = self.designs.set(p.value, self.matching.last_ns, self.node.get_logger())
                if reason is not None:
                    return SetParametersResult(False, reason)
        return SetParametersResult(True)

    def activate(self) -> None:
        """Control again from the next estimate (when ``enabled``)."""
        super().activate()
        self.controller.enabled = self.enabled

    def deactivate(self) -> None:
        """Zero commands from the next estimate on, published as usual (the simulator in
        lock-step still gets its answer)."""
        super().deactivate()
        self.controller.enabled = False

    def reset(self) -> None:
        """A new controller from the scene (``cleanup``), its settings kept."""
        limit, enabled = self.controller.limit, self.controller.enabled
        self.controller = make_controller(self.params.scene, design_model(self.params.scene))
        self.controller.set_limit(limit)
        self.controller.enabled = enabled
        self.watchdog = EstimateWatchdog(self.controller, self.grid)

    def subscribe_inputs(self) -> None:
        """Subscribe the state estimates and the load cell's wrench (and ``/clock`` with
        ``use_sim_time``, for the watchdog), each through its writer gate."""
        est, wrench, clock = topics.STATE_ESTIMATE, topics.EXCITATION_WRENCH, topics.CLOCK
        token = self.params.run_token
        fast_inputs.subscribe(self.node, est.type_name, est.name, self.params.reader_qos(est),
                              estimate_reader(token), self.on_estimate,
                              self.gates.add(est.name, "estimate_writer"))
        fast_inputs.subscribe(self.node, wrench.type_name, wrench.name,
                              self.params.reader_qos(wrench),
                              wrench_reader("floor1", "wrench.force.x", token), self.on_force,
                              self.gates.add(wrench.name, "sensor_writer"))
        if self.sim_time:       # the watchdog follows the simulator's /clock (module docstring)
            fast_inputs.subscribe(self.node, clock.type_name, clock.name, clock.qos,
                                  clock_reader(), self.on_clock,
                                  self.gates.add(clock.name, "sensor_writer", stamped=False))

    def on_force(self, ns: int, force: float) -> None:
        """The excitation force [N] stamped ``ns`` into the matching (the input's age restarts)."""
        self.input_at = time.monotonic()
        self.matching.add_force(ns, force)

    def on_clock(self, ns: int) -> None:
        """The simulator's ``/clock`` [ns], the time the watchdog follows with ``use_sim_time``."""
        self.clock_ns = ns

    def on_estimate(self, ns: int, physical: np.ndarray, applied: np.ndarray) -> None:
        """The state estimate stamped ``ns`` (physical coordinates, the actuation it took as
        applied) into the matching, to be answered when its load cell is in."""
        self.matching.add_estimate(ns, physical, time.monotonic_ns(), applied)

    def process_ready(self) -> int:
        """Answer pending estimates in order (in lock-step each waits for its load cell); how
        many were answered."""
        if self.matching.take_jump():        # a new run of the loop: disarm the watchdog
            self.controller.latest = None
            self.watchdog = EstimateWatchdog(self.controller, self.grid)
        answered = 0
        timing, slot = self.timing, self.slot
        while (m := self.matching.pop_ready(now := time.monotonic_ns())) is not None:
            started = time.perf_counter()
            timing.begin(m.ns)
            timing.mark_at(slot["estimate_in"], m.arrival_ns)
            timing.mark_at(slot["ready"], now)
            self.sample_start_ns = m.arrival_ns
            if (due := self.designs.due(m.ns)) is not None:
                design, taken = due
                self.controller.take_law(taken)
                self.to_design = design_map(design)
                self.node.get_logger().info(f"design {self.designs.current!r} taken at "
                                            f"t = {self.grid.seconds(m.ns):.6g} s")
            t = self.grid.seconds(m.ns)
            estimate = Estimate(t, self.to_design @ m.physical, m.physical, applied=m.applied)
            command = self.controller.command(t, estimate, m.force)
            timing.mark(slot["computed"])
            self.send(command)
            self.compute.add(time.perf_counter() - started)
            self.rate.tick()
            answered += 1
        return answered

    def send(self, command: Command) -> None:
        """Publish ``command``; the law's (not the watchdog's) marks the sample's phases."""
        timing = self.timing if not command.watchdog else None
        cdr = self.out.cdr(command, self.grid.ns(command.t))
        if timing is not None:
            timing.mark(self.slot["serialized"])
        self.pub.publish(cdr)
        if timing is not None:
            timing.mark(self.slot["written"])
        self.last_command = command

    def check(self) -> None:
        """Command zero at the newest sample time seen (load cell, or ``/clock`` with
        ``use_sim_time``) when the estimates are stale (module docstring)."""
        ns = self.matching.sample_ns
        if self.sim_time:
            ns = max(ns, self.clock_ns)
        t = self.watchdog.due(ns, self.matching.waiting)
        if t is None:
            return
        if not self.last_command.watchdog:
            self.node.get_logger().warning(f"watchdog: no fresh estimate at t = {t:.4g} s; "
                                           "commanding zero")
        self.send(self.controller.command(t, None, self.matching.force))

    def status(self) -> tuple[dict[str, Any], int, str]:
        """``/diagnostics``: the command counts (saturated, singular, watchdog, runaway, fallback),
        the design, the last command, the matching's counts, the writer gates, the compute time
        percentiles [ms] and the input's age [s]; ERROR while the watchdog commands zero or no load
        cell came for ``stale_input_s``, WARN on any other problem or a refused writer."""
        c = self.controller.counters
        cmd = self.last_command
        values = {"mode": self.params.mode, "rate_hz": self.rate.read(),
                  "commands": c.commands, "saturated": c.saturated, "singular": c.singular,
                  "watchdog": c.watchdog, "watchdog_active": cmd.watchdog,
                  "runaway": c.runaway, "fallback": c.fallback,
                  "enabled": cmd.enabled, "design": self.designs.current,
                  "designs_taken": self.designs.taken,
                  "last_command": float(cmd.vector[self.controller.actuator]),
                  **self.matching.counts,
                  "refused_writers": self.gates.refused(), **self.gates.values(),
                  **{f"compute_ms_{k}": v for k, v in self.compute.recent().items()}}
        problems = [text for flag, text in (
            (cmd.watchdog, f"watchdog: no fresh estimate for {self.controller.watchdog_periods} "
                           "periods (estimator stale or gone); commanding zero"),
            (c.runaway, f"control law output non-finite or beyond {RUNAWAY_FACTOR:g}x the "
                        f"limit {c.runaway} times"),
            (c.fallback, f"MPC solve failed {c.fallback} times; the anti-windup LQG command "
                         "was sent instead"),
        ) if flag]
        if intruders := self.gates.message():
            problems.append(intruders)
        idle_s = 0.0 if self.input_at is None else time.monotonic() - self.input_at
        values["input_age_s"] = idle_s
        if idle_s > self.params.stale_input_s:
            problems.append(f"stale input: no load-cell reading for {idle_s:.3g} s "
                            "(simulator stale or gone)")
        level = ERROR if cmd.watchdog or idle_s > self.params.stale_input_s else (
            WARN if problems or values["refused_writers"] else OK)
        return values, level, "; ".join(problems)

    def status_stamp(self) -> int:
        """The stamp of the status [ns]: the newest estimate matched (0 before the first)."""
        return max(self.matching.last_ns, 0)

    def peers_ready(self) -> bool:
        """Whether the command's publisher has matched every subscriber the graph shows, the
        simulator's (or the pinned sensor writer's node) among them
        (:func:`~stillframe.node_runtime.support.reaches_peer`)."""
        return reaches_peer(self.node, self.pub, self.gates.pins["sensor_writer"] or SIM)

    def start(self) -> None:
        """Wait for the command's subscribers in lock-step, then take the inputs."""
        if self.params.lockstep:
            self.node.get_logger().info("lock-step: waiting for the simulator")
            wait_for_peers(self.node, self.peers_ready)
        self.subscribe_inputs()

    def mid_sample(self) -> bool:
        """The load cell of the sample after the last estimate is in, less than a period ago,
        and its estimate not yet (estimates further behind are the watchdog's: not a sample in
        progress)."""
        m, period = self.matching, self.params.period
        return (m.last_ns >= 0 and 0 < m.sample_ns - m.last_ns <= round(period * 1e9)
                and self.input_at is not None and time.monotonic() - self.input_at < period)

    def next_wait(self) -> float:
        """The longest wait of the next spin [s]: until the oldest estimate waiting for its load
        cell times out, at most 0.05 s."""
        left = self.matching.wait_ns_left(time.monotonic_ns())
        return 0.05 if left is None else min(left * 1e-9, 0.05)


@api.node_main
def main() -> int:
    """Run the node (console script ``controller_node``); bad parameters exit 2 with one line."""
    return base.main(ControllerNode)


if __name__ == "__main__":
    sys.exit(main())
