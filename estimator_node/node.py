"""estimator_node: the scene's estimator on the topic contract (docs/nodes.md).

A thin shell around :func:`stillframe.estimation.factory.make_estimator`. It collects the readings
of
one stamp t_k from the floor IMUs, the encoder and the load cell (and ``state_truth`` for the
``truth`` estimator), then calls ``step(sample, command in effect)`` and publishes
``state_estimate`` and ``state_estimate/covariance`` stamped t_k. The actuation in effect is what
the simulator reports it applied over the previous period (after saturation and slew limits):
the encoder's ``effort`` (hinge torque) and ``floor3/load_cell`` (floor-3 force), so that a
saturated actuator does not wind the estimate up; where a sample carries no such reading, the
newest command received on ``pendulum/torque_cmd`` and ``floor3/force_cmd``. In lock-step a
stamp of a scene driving the floor-3 force waits for its ``floor3/load_cell`` reading too. The
actuator the scene's controller does not drive is taken as zero (the sim refuses its commands),
whatever arrives on its topics.

- ``mode: lockstep``: a stamp is used once all its channels arrived and the command stamped
  t_k−1 did (the previous step's answer); after half of ``lockstep_timeout_s`` without them
  (so that the loop still answers before the simulator's own timeout), or when a
  newer stamp arrives first, it is used with what arrived (a partial update).
- ``mode: realtime``: a stamp is used when complete, when a newer one arrives, or
  ``partial_after_s`` after its first message, with what arrived.

Parameters settable at run time (Kalman filters and EKF; refused with a reason, and the loop goes
on, when the value is wrong): ``process_noise_std`` (8 finite values ≥ 0) and
``measurement_noise_std`` (4 finite values > 0), the filter's W0 and V0 (thesis eq. 5.221–5.222),
starting at the scene's ``estimator`` values; what depends on them (Q, R, and for ``kf`` the
stationary covariance and gain) is recomputed before the next sample. Every other parameter is
read-only.

An estimator started while the loop runs (its first sample stamped after 0, e.g. restarted after
a crash) starts a Kalman filter's mean from that sample's measurements
(:meth:`stillframe.estimation.kalman.LinearFilter.initialise_from`) rather than the scene's initial
state,
at the first sample that carries all four measurements (earlier ones are skipped and counted).

Messages older than the last stamp used are rejected and counted (``stale_messages``); NaN or
Inf readings are dropped by the filter and counted (``non_finite``).
"""

from __future__ import annotations

import functools
import sys
import time
from typing import Any

import numpy as np

from stillframe.contract import messages, topics
from stillframe.contract.codecs import (
    COMMAND_TOPICS,
    EstimateMessages,
    SampleGrid,
    applied_torque,
    command_value,
    physical_state,
    sensor_reading,
)
from stillframe.contract.signals import Sample, actuator_of
from stillframe.dynamics.models.identified import frame_for
from stillframe.errors import InputError
from stillframe.estimation.base import Filter
from stillframe.estimation.factory import make_estimator
from stillframe.estimation.kalman import LinearFilter
from stillframe.loop.node_support import (
    OK,
    WARN,
    Diagnostics,
    Durations,
    LoopParameters,
    RateMeter,
    check_settable,
    declare_loop_parameters,
    has_publisher,
    wait_for_peers,
)
from stillframe.middleware import api
from stillframe.middleware.params import Parameter, SetParametersResult, finite_floats

SENSOR_TOPICS = (*topics.FLOOR_IMU, topics.PENDULUM_JOINT_STATES, topics.EXCITATION_WRENCH)
ENCODER_CHANNEL = SENSOR_TOPICS.index(topics.PENDULUM_JOINT_STATES)


class Pending:
    """The channels of one stamp received so far."""

    def __init__(self, ns: int) -> None:
        self.ns = ns
        self.values = np.full(5, np.nan)
        self.present = np.zeros(5, dtype=bool)
        self.truth: np.ndarray | None = None
        self.applied = np.full(2, np.nan)    # [torque, force] applied over the previous period
        self.first = time.monotonic()


class EstimatorNode:
    """The estimator, its subscriptions, and the per-stamp assembly of samples."""

    def __init__(self, node: api.Node, params: LoopParameters, partial_after_s: float) -> None:
        self.node = node
        self.params = params
        scene = params.scene
        design = frame_for(scene.design.model, scene.design.file, scene, "design.file")
        self.estimator = make_estimator(scene, design)
        self.needs_truth = scene.estimator.type == "truth"
        self.active = actuator_of(scene)
        self.grid = SampleGrid(params.period)
        self.wait_s = params.lockstep_timeout_s / 2 if params.lockstep else partial_after_s
        spec, cov = topics.STATE_ESTIMATE, topics.STATE_COVARIANCE
        self.state_pub = node.create_publisher(spec.type_name, spec.name, spec.qos)
        self.cov_pub = node.create_publisher(cov.type_name, cov.name, cov.qos)
        self.out = EstimateMessages()
        self.diagnostics = Diagnostics(node, params.diagnostics_period_s)
        for i, spec in enumerate(COMMAND_TOPICS):
            node.create_subscription(spec.type_name, spec.name,
                                     functools.partial(self.on_command, i), spec.qos)
        self.command = np.zeros(2)
        self.command_ns = [-1, -1]
        self.pending: dict[int, Pending] = {}
        self.last_ns = -1
        self.counts = {"estimates": 0, "stale_messages": 0, "partial_updates": 0,
                       "rejected_commands": 0, "command_waits_timed_out": 0,
                       "applied_reported": 0, "initialised_from_measurements": 0,
                       "skipped_before_initialisation": 0}
        self.compute = Durations()
        self.rate = RateMeter()
        if isinstance(self.estimator, Filter):
            self.declare_run_time_parameters()
        else:
            node.add_on_set_parameters_callback(check_settable)   # truth: nothing to tune

    # -- parameters ----------------------------------------------------------------------
    def declare_run_time_parameters(self) -> None:
        """The noise settings (from the command line, else the scene), applied now and on
        every accepted set."""
        config = self.params.scene.estimator
        self.noise = {"process_noise_std": list(config.process_noise_std),
                      "measurement_noise_std": list(config.measurement_noise_std)}
        declared = [self.node.declare_parameter(name, value)
                    for name, value in self.noise.items()]
        result = self.on_set_parameters(declared)
        if not result.successful:
            raise InputError(f"parameter {result.reason}")
        self.node.add_on_set_parameters_callback(self.on_set_parameters)

    def on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Check the new noise settings and redesign the filter with them (all or nothing)."""
        settable = check_settable(parameters, frozenset(self.noise))
        if not settable.successful:
            return settable
        noise = dict(self.noise)
        for p in parameters:
            if p.name in noise:
                length = len(noise[p.name])
                reason = finite_floats(p.value, p.name, length)
                if not reason and p.name == "process_noise_std" and min(p.value) < 0:
                    reason = f"{p.name}: must be >= 0, got {p.value}"
                if not reason and p.name == "measurement_noise_std" and min(p.value) <= 0:
                    reason = f"{p.name}: must be > 0, got {p.value}"
                if reason:
                    return SetParametersResult(False, reason)
                noise[p.name] = list(p.value)
        try:
            self.estimator.set_noise(noise["process_noise_std"], noise["measurement_noise_std"])
        except InputError as exc:
            return SetParametersResult(False, str(exc))
        self.noise = noise
        return SetParametersResult(True)

    # -- inputs --------------------------------------------------------------------------
    def subscribe_sensors(self) -> None:
        for channel, spec in enumerate(SENSOR_TOPICS):
            self.node.create_subscription(spec.type_name, spec.name,
                                          functools.partial(self.on_sensor, channel),
                                          self.params.qos(spec))
        if self.active == 1:    # the applied floor-3 force matters only when it is driven
            spec = topics.FLOOR3_LOAD_CELL
            self.node.create_subscription(spec.type_name, spec.name, self.on_applied_force,
                                          self.params.qos(spec))
        if self.needs_truth:
            spec = topics.STATE_TRUTH
            self.node.create_subscription(spec.type_name, spec.name, self.on_truth, spec.qos)

    def slot(self, msg: Any) -> Pending | None:
        ns = messages.stamp_ns(msg.header.stamp)
        if ns <= self.last_ns:
            self.counts["stale_messages"] += 1
            return None
        return self.pending.setdefault(ns, Pending(ns))

    def on_sensor(self, channel: int, msg: Any) -> None:
        if (p := self.slot(msg)) is not None:
            p.values[channel] = sensor_reading(channel, msg)
            p.present[channel] = True
            if channel == ENCODER_CHANNEL:
                p.applied[0] = applied_torque(msg)

    def on_applied_force(self, msg: Any) -> None:
        if (p := self.slot(msg)) is not None:
            p.applied[1] = float(msg.wrench.force.x)

    def on_truth(self, msg: Any) -> None:
        if (p := self.slot(msg)) is not None:
            p.truth = physical_state(msg)

    def on_command(self, actuator: int, msg: Any) -> None:
        ns = messages.stamp_ns(msg.header.stamp)
        value = command_value(actuator, msg)
        if not np.isfinite(value) or ns < self.command_ns[actuator]:
            self.counts["rejected_commands"] += 1
            return
        self.command[actuator], self.command_ns[actuator] = value, ns

    # -- stepping ------------------------------------------------------------------------
    def complete(self, p: Pending) -> bool:
        return (bool(p.present.all()) and (p.truth is not None or not self.needs_truth)
                and (self.active != 1 or not np.isnan(p.applied[1])))

    def command_in(self) -> bool:
        """In lock-step, the answer to the previous stamp has arrived (or none is expected)."""
        return (not self.params.lockstep or self.active is None or self.last_ns < 0
                or self.command_ns[self.active] >= self.last_ns)

    def process_ready(self) -> None:
        """Use every pending stamp that is ready, oldest first."""
        while self.pending:
            ns = min(self.pending)
            p = self.pending[ns]
            newer = len(self.pending) > 1
            timed_out = time.monotonic() - p.first >= self.wait_s
            complete = self.complete(p)
            if not (newer or timed_out or (complete and self.command_in())):
                return
            if complete and not self.command_in():
                self.counts["command_waits_timed_out"] += 1
            self.use(self.pending.pop(ns), complete)

    def use(self, p: Pending, complete: bool) -> None:
        started = time.perf_counter()
        self.counts["partial_updates"] += not complete
        sample = Sample(self.grid.seconds(p.ns), p.values[:4].copy(), float(p.values[4]),
                        p.present.copy(), p.truth)
        reported = np.isfinite(p.applied)
        control = np.where(reported, p.applied, self.command)
        control[[i for i in (0, 1) if i != self.active]] = 0.0   # the sim drives only this one
        self.counts["applied_reported"] += bool(reported[self.active or 0])
        if self.last_ns < 0 and p.ns > 0 and isinstance(self.estimator, LinearFilter):
            # joined a running loop (restarted): start from the measurements, not the scene,
            # at the first sample that carries all of them
            if not (p.present[:4].all() and np.isfinite(p.values[:4]).all()):
                self.counts["skipped_before_initialisation"] += 1
                return
            self.estimator.initialise_from(sample, control)
            self.counts["initialised_from_measurements"] += 1
        estimate = self.estimator.step(sample, control)
        self.last_ns = p.ns
        if estimate is None:
            return
        state, cov = self.out.fill(estimate, p.ns)
        self.state_pub.publish(state)
        self.cov_pub.publish(cov)
        self.compute.add(time.perf_counter() - started)
        self.counts["estimates"] += 1
        self.rate.tick()

    def next_wait(self) -> float:
        if not self.pending:
            return 0.1
        first = min(p.first for p in self.pending.values())
        return min(0.1, max(0.0, first + self.wait_s - time.monotonic()))

    def publish_status(self) -> None:
        c = self.estimator.counters
        values = {"mode": self.params.mode, "rate_hz": self.rate.read(), **self.counts,
                  "updates": c.updates, "stale": c.stale, "non_finite": c.non_finite,
                  "missing": c.missing, "rejected": c.rejected + self.counts["stale_messages"],
                  **{f"compute_ms_{k}": v for k, v in self.compute.summary().items()}}
        level = WARN if values["rejected"] or self.counts["partial_updates"] else OK
        self.diagnostics.publish(max(self.last_ns, 0), values, level)

    def peers_ready(self) -> bool:
        """The controller reads the estimates and publishes the scene's command topic."""
        return self.state_pub.get_subscription_count() > 0 and has_publisher(
            self.node, COMMAND_TOPICS[self.active].name)

    def run(self) -> None:
        """Wait for the controller in lock-step, then estimate until shutdown."""
        if self.params.lockstep and self.active is not None:
            self.node.get_logger().info("lock-step: waiting for the controller")
            while api.ok() and not wait_for_peers(self.node, self.peers_ready, 1.0):
                pass
        self.subscribe_sensors()
        while api.ok():
            self.node.spin_once(self.next_wait())
            self.process_ready()
            if self.diagnostics.due():
                self.publish_status()
        self.publish_status()


@api.node_main
def main() -> int:
    """Run the node (console script ``estimator_node``); bad parameters exit 2 with one line."""
    node = api.create_node("estimator_node", namespace=topics.DEFAULT_NAMESPACE)
    try:
        params = declare_loop_parameters(node)
        partial = node.declare_parameter("partial_after_s", 0.5 * params.period,
                                         read_only=True).value
        if not partial > 0:
            raise InputError(f"parameter 'partial_after_s': must be > 0, got {partial}")
        EstimatorNode(node, params, float(partial)).run()
    finally:
        node.destroy_node()
    return 0


if __name__ == "__main__":
    sys.exit(main())
