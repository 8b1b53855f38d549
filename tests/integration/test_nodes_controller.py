"""controller_node as a process, fed by a probe playing simulator and estimator: its commands
equal the in-process controller's, and when the estimates stop while the samples go on (seen
through the load cell's stamps, or through ``/clock`` with ``use_sim_time``), the watchdog
zeroes the command after ``watchdog_periods`` periods and says so on ``/diagnostics``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stillframe.contract import messages, topics
from stillframe.contract.codecs import EstimateMessages
from stillframe.contract.signals import Estimate
from stillframe.control.factory import make_controller
from stillframe.design.coordinates import to_design
from stillframe.loop.wiring import design_model
from stillframe.middleware.api import create_node, spin_until
from stillframe.middleware.clock import ClockPublisher
from stillframe.node_runtime.support import LoopParameters, diagnostic_values
from tests.support.nodes import params_file, start_node, stop
from tests.support.scenes import thesis_scene
from tests.support.waits import HANG_S

OVERRIDES = ["duration=1", "controller.start=0.0625", "evaluation.window=0.0625",
             "controller.feedforward=true"]
ESTIMATED = 8          # samples with an estimate; then only /clock and the load cell
STEPS = 13


@pytest.mark.parametrize("time_source", ["load_cell", "clock"])
def test_commands_and_watchdog(ros_domain: int, tmp_path: Path, time_source: str) -> None:
    """After the estimates stop, only the load cell (no sim time) or only ``/clock`` (with
    ``use_sim_time``) goes on."""
    scene = thesis_scene("thesis_lqg", OVERRIDES)
    period = 1.0 / scene.sensors.rate_hz
    rng = np.random.default_rng(3)
    states = 1e-3 * rng.standard_normal((ESTIMATED, 8))
    forces = 0.1 * rng.standard_normal(STEPS)
    # the probe stands in for the simulator, so the pin names it (the start-up waits for it)
    proc = start_node("controller_node", params_file(tmp_path, "thesis_lqg", OVERRIDES,
                                                     use_sim_time=time_source == "clock",
                                                     diagnostics_period_s=0.2,
                                                     sensor_writer="probe"))
    probe = create_node("probe", namespace=topics.DEFAULT_NAMESPACE, argv=["test"])
    try:
        clock = ClockPublisher(probe)
        est = probe.create_publisher(topics.STATE_ESTIMATE.type_name, topics.STATE_ESTIMATE.name,
                                     topics.STATE_ESTIMATE.qos)
        sim_qos = LoopParameters(scene, "lockstep", 0.2).qos(topics.EXCITATION_WRENCH)
        wrench = probe.create_publisher(topics.EXCITATION_WRENCH.type_name,
                                        topics.EXCITATION_WRENCH.name, sim_qos)
        commands, diagnostics = [], []
        probe.create_subscription(topics.TORQUE_CMD.type_name, topics.TORQUE_CMD.name,
                                  commands.append, topics.TORQUE_CMD.qos)
        probe.create_subscription(topics.DIAGNOSTICS.type_name, topics.DIAGNOSTICS.name,
                                  diagnostics.append, topics.DIAGNOSTICS.qos)
        assert spin_until(probe, lambda: est.get_subscription_count() > 0, HANG_S)
        spin_until(probe, lambda: False, 0.3)
        out = EstimateMessages()
        load = messages.new("geometry_msgs/msg/WrenchStamped")
        for k in range(STEPS):
            ns = round(k * period * 1e9)
            load.header.stamp = messages.time_msg(ns)
            load.wrench.force.x = forces[k]
            if k < ESTIMATED or time_source == "clock":
                clock.publish(ns)
            if k < ESTIMATED or time_source == "load_cell":
                wrench.publish(load)
            if k < ESTIMATED:
                est.publish(out.fill(Estimate(k * period, states[k], states[k]), ns)[0])
                assert spin_until(probe, lambda k=k: len(commands) == k + 1, HANG_S), k
            else:
                spin_until(probe, lambda: False, 0.1)

        trips = STEPS - (ESTIMATED - 1 + scene.controller.watchdog_periods)

        def tripped() -> bool:
            return len(commands) == ESTIMATED + trips and bool(diagnostics) and (
                diagnostic_values(diagnostics[-1])["watchdog"] == str(trips))

        assert spin_until(probe, tripped, HANG_S)
    finally:
        probe.destroy_node()
        code, err = stop(proc)
    assert code == 0, err[-2000:]

    design = design_model(scene)
    reference = make_controller(scene, design)
    for k in range(ESTIMATED):
        t = k * period
        c = reference.command(t, Estimate(t, to_design(design, states[k]), states[k]), forces[k])
        assert messages.stamp_ns(commands[k].header.stamp) == round(t * 1e9)
        assert commands[k].wrench.torque.z == c.torque
    assert commands[0].wrench.torque.z == 0.0 and commands[2].wrench.torque.z != 0.0  # start
    # The newest estimate is t_7; at t_10 it is 3 periods (watchdog_periods) old.
    watchdog = commands[ESTIMATED:]
    first = ESTIMATED - 1 + scene.controller.watchdog_periods
    assert [messages.stamp_ns(m.header.stamp) for m in watchdog] == [
        round(k * period * 1e9) for k in range(first, STEPS)]
    assert all(m.wrench.torque.z == 0.0 for m in watchdog)
    assert reference.command(first * period, None, 0.0).watchdog
    assert not reference.command((first - 1) * period, None, 0.0).watchdog
    values = diagnostic_values(diagnostics[-1])
    assert values["watchdog"] == str(STEPS - first) and values["watchdog_active"] == "True"
    assert diagnostics[-1].status[0].level == 2     # ERROR: the estimator is stale or gone
    assert "watchdog" in diagnostics[-1].status[0].message
