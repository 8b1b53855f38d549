"""estimator_node as a process, fed by a probe playing simulator and controller: its estimates
equal the in-process estimator's on the same samples and commands, including a NaN reading
(dropped and counted), a stale message (rejected and counted) and a missing channel (a partial
update: in lock-step only once the next stamp arrives on the missing channel's own topic, never
after a wall-clock wait, and not before a late message of that stamp on another topic). The
probe's "simulator" saturates the torque at :data:`TORQUE_LIMIT` and reports the applied torque
in the encoder's ``effort``: the estimator uses that, not the command (no windup); where no
effort is reported, the command in effect while the sim's last report matched the commands, else
(here: saturated) that report. In real time, a reading that comes after its stamp was used
without it re-runs the filter from that stamp."""

from __future__ import annotations

import signal
from pathlib import Path

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract import messages, topics
from stillframe.contract.codecs import ENCODER_CHANNEL, SensorMessages
from stillframe.contract.signals import Sample
from stillframe.estimation.factory import make_estimator
from stillframe.loop.wiring import design_model
from stillframe.middleware.api import create_node, spin_until
from stillframe.node_runtime.support import LoopParameters, diagnostic_values
from stillframe.plant.frame_plant import FramePlant
from tests.support.nodes import SHORT_LQG, params_file, start_node, stop
from tests.support.scenes import thesis_scene
from tests.support.waits import HANG_S

STEPS = 6
NAN_STEP, MISSING_STEP = 2, 4   # floor-2 reading NaN; encoder not sent
TORQUE_LIMIT = 0.12


def _samples() -> list[Sample]:
    plant = FramePlant(thesis_scene("thesis_lqg", SHORT_LQG))
    out = []
    for _ in range(STEPS):
        s = plant.sample()
        out.append(s)
        plant.advance(np.zeros(2))
    out[NAN_STEP].measurements[1] = np.nan
    out[MISSING_STEP].present[3] = False
    return out


def test_estimates_nan_stale_and_missing_channels(ros_domain: int, tmp_path: Path) -> None:
    scene = thesis_scene("thesis_lqg", SHORT_LQG)
    samples = _samples()
    commands = [0.05 * (k + 1) for k in range(STEPS)]
    applied = [0.0, *np.minimum(commands[:-1], TORQUE_LIMIT)]   # over the period before k
    for s, torque in zip(samples, applied, strict=True):
        s.applied = np.array([torque, 0.0])
    # the probe stands in for the controller, so the pin names it (the start-up waits for it)
    proc = start_node("estimator_node", params_file(tmp_path, "thesis_lqg", SHORT_LQG,
                                                    diagnostics_period_s=0.2,
                                                    command_writer="probe"))
    probe = create_node("probe", namespace=topics.DEFAULT_NAMESPACE, argv=["test"])
    try:
        loop = LoopParameters(scene, "lockstep", 0.2)   # the sim's sensor QoS
        sensors = [probe.create_publisher(s.type_name, s.name, loop.qos(s)) for s in
                   (*topics.FLOOR_IMU, topics.PENDULUM_JOINT_STATES, topics.EXCITATION_WRENCH)]
        cmd = probe.create_publisher(topics.TORQUE_CMD.type_name, topics.TORQUE_CMD.name,
                                     topics.TORQUE_CMD.qos)
        estimates, covariances, diagnostics = [], [], []
        for spec, sink in ((topics.STATE_ESTIMATE, estimates),
                           (topics.STATE_COVARIANCE, covariances),
                           (topics.DIAGNOSTICS, diagnostics)):
            probe.create_subscription(spec.type_name, spec.name, sink.append, spec.qos)
        assert spin_until(probe, lambda: all(p.get_subscription_count() for p in sensors), HANG_S)
        spin_until(probe, lambda: False, 0.3)
        wire = SensorMessages(scene.sensors)
        def send(s: Sample, channels: range = range(5)) -> None:
            ns = round(s.t * 1e9)
            for channel, (pub, msg) in enumerate(zip(sensors, wire.fill(s, ns)[:5], strict=True)):
                if s.present[channel] and channel in channels:
                    pub.publish(msg)

        for k, s in enumerate(samples):
            ns = round(s.t * 1e9)
            if k != MISSING_STEP + 1:       # sent already, right after the incomplete one
                send(s, range(4) if k == MISSING_STEP else range(5))
            if k == NAN_STEP:   # a late floor-1 reading of the previous stamp: stale
                stale = wire.fill(samples[k - 1], round(samples[k - 1].t * 1e9))[0]
                sensors[0].publish(stale)
            if k == MISSING_STEP:   # lock-step: the next stamp makes the incomplete one partial
                # but only with all of it that comes: the excitation, late (after the next
                # stamp's other topics, before its own), still goes into it
                send(samples[k + 1], range(4))
                spin_until(probe, lambda: False, 0.3)
                send(s, range(4, 5))
                send(samples[k + 1], range(4, 5))
            assert spin_until(probe, lambda k=k: len(estimates) == k + 1, HANG_S), k
            answer = messages.new("geometry_msgs/msg/WrenchStamped")
            answer.header.stamp = messages.time_msg(ns)
            answer.wrench.torque.z = commands[k]
            cmd.publish(answer)

        def counted() -> bool:
            return len(covariances) == STEPS and bool(diagnostics) and diagnostic_values(
                diagnostics[-1]).get("estimates") == str(STEPS)

        assert spin_until(probe, counted, HANG_S)
    finally:
        probe.destroy_node()
        code, err = stop(proc, signal.SIGTERM)
    assert code == 0, err[-2000:]

    design = design_model(scene)
    reference = make_estimator(scene, design)
    for k, s in enumerate(samples):
        # the missing encoder carried no effort: the sim's last report (the saturated 0.12 for
        # sample 2's 0.15) showed it not applying the commands, so that report is held, not
        # the command in effect (0.20)
        torque = applied[k - 1] if k == MISSING_STEP else applied[k]
        assert k != MISSING_STEP or (torque, commands[k - 1]) == (TORQUE_LIMIT, 0.2)
        e = reference.step(s, np.array([torque, 0.0]))
        msg = estimates[k]
        assert messages.stamp_ns(msg.header.stamp) == round(s.t * 1e9)
        assert list(msg.name) == ["x1", "x2", "x3", "phi"]
        np.testing.assert_array_equal(np.r_[msg.position, msg.velocity], e.physical)
        np.testing.assert_array_equal(covariances[k].data.reshape(8, 8), e.covariance)
    values = diagnostic_values(diagnostics[-1])
    assert values["non_finite"] == "1" and reference.counters.non_finite == 1
    assert values["stale_messages"] == "1"
    assert values["missing"] == "1" and values["estimates"] == str(STEPS)
    assert values["rejected"] == "2"
    assert values["applied_reported"] == str(STEPS - 1)
    assert diagnostics[-1].status[0].level == 1   # WARN


LATE = 3            # the stamp whose encoder reading comes after its stamp was used


def _plant_samples(scene: Scene) -> list[Sample]:
    """STEPS complete samples of the thesis plant from the scene's start, each reporting the
    torque applied over the period before it."""
    plant = FramePlant(scene)
    out = []
    for k in range(STEPS):
        s = plant.sample()
        s.present = np.ones(5, dtype=bool)
        s.applied = np.array([0.01 * k, 0.0])
        out.append(s)
        plant.advance(s.applied)
    return out


def test_realtime_late_reading_refilters_to_the_in_time_estimates(ros_domain: int,
                                                                  tmp_path: Path) -> None:
    """Real time: stamp LATE's encoder reading (with the torque applied) is held back until the
    estimator has used that stamp without it (a partial update after ``partial_after_s``, with
    the command in effect: none yet, zero); sent then, it is taken (``late_inputs``) and the
    filter steps again from that stamp (``refilters``). Every later estimate equals, to the last
    bit, the in-process filter's on the complete samples; the partial one stays as published."""
    scene = thesis_scene("thesis_lqg", SHORT_LQG)
    samples = _plant_samples(scene)
    proc = start_node("estimator_node", params_file(tmp_path, "thesis_lqg", SHORT_LQG,
                                                    mode="realtime", partial_after_s=3.0,
                                                    diagnostics_period_s=0.2,
                                                    command_writer="probe"))
    probe = create_node("probe", namespace=topics.DEFAULT_NAMESPACE, argv=["test"])
    try:
        loop = LoopParameters(scene, "realtime", 0.2)
        sensors = [probe.create_publisher(s.type_name, s.name, loop.qos(s)) for s in
                   (*topics.FLOOR_IMU, topics.PENDULUM_JOINT_STATES, topics.EXCITATION_WRENCH)]
        estimates, diagnostics = [], []
        probe.create_subscription(topics.STATE_ESTIMATE.type_name, topics.STATE_ESTIMATE.name,
                                  estimates.append, topics.STATE_ESTIMATE.qos)
        probe.create_subscription(topics.DIAGNOSTICS.type_name, topics.DIAGNOSTICS.name,
                                  diagnostics.append, topics.DIAGNOSTICS.qos)
        assert spin_until(probe, lambda: all(p.get_subscription_count() for p in sensors), HANG_S)
        spin_until(probe, lambda: False, 0.3)
        wire = SensorMessages(scene.sensors)

        def send(s: Sample, channels: list[int]) -> None:
            msgs = wire.fill(s, round(s.t * 1e9))[:5]
            for channel in channels:
                sensors[channel].publish(msgs[channel])

        def counts(**want: str) -> bool:
            return bool(diagnostics) and all(
                diagnostic_values(diagnostics[-1]).get(k) == v for k, v in want.items())

        for k, s in enumerate(samples):
            send(s, [c for c in range(5) if k != LATE or c != ENCODER_CHANNEL])
            assert spin_until(probe, lambda k=k: len(estimates) == k + 1, HANG_S), k
            if k == LATE:       # used without it (partial): now the encoder's reading comes
                send(s, [ENCODER_CHANNEL])
                assert spin_until(probe, lambda: counts(late_inputs="1", refilters="1"), HANG_S)
        assert spin_until(probe, lambda: counts(estimates=str(STEPS)), HANG_S)
    finally:
        probe.destroy_node()
        code, err = stop(proc, signal.SIGTERM)
    assert code == 0, err[-2000:]

    values = diagnostic_values(diagnostics[-1])
    assert (values["partial_updates"], values["stale_messages"]) == ("1", "0")
    design = design_model(scene)
    in_time, partial = make_estimator(scene, design), make_estimator(scene, design)
    for k, s in enumerate(samples):
        e = in_time.step(s, s.applied)
        if k == LATE:   # as used: no encoder, no report of the torque, no command yet
            held = Sample(s.t, s.measurements.copy(), s.force, s.present.copy())
            held.present[ENCODER_CHANNEL] = False
            held.measurements[ENCODER_CHANNEL] = np.nan
            e = partial.step(held, np.zeros(2))
        elif k < LATE:
            partial.step(s, s.applied)
        msg = estimates[k]
        assert messages.stamp_ns(msg.header.stamp) == round(s.t * 1e9)
        np.testing.assert_array_equal(np.r_[msg.position, msg.velocity], e.physical, err_msg=k)
