"""What each hop of one real-time sample costs, measured piece by piece in one process
(``stillframe bench hops``).

The sample path through the three nodes (docs/realtime.md): sim_node takes the plant's sample and
serializes and writes its seven messages; the estimator reads five of them, steps its filter and
writes the estimate and its covariance; the controller reads the estimate and the load cell,
computes and writes the command; sim_node reads it and advances the plant. Each piece is timed
here on its own (median of ``repeats`` rounds of ``number`` calls), with the ``rosbags`` CDR beside
the fixed-layout codecs (:mod:`stillframe.contract.fixed_cdr`) measured in the same run, and the
DDS write and read of each backend through a publisher and a subscription of one process. What a
single process cannot show, the wake-up of another process, is `bench transport`'s round trip.
"""

from __future__ import annotations

import dataclasses
import itertools
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract import messages, topics
from stillframe.contract.codecs import (
    COMMAND_TOPICS,
    SAMPLE_TOPICS,
    SENSOR_TOPICS,
    CommandMessage,
    EstimateMessages,
    SensorMessages,
    command_reader,
    estimate_reader,
    sensor_reader,
)
from stillframe.contract.signals import actuator_of
from stillframe.control.factory import make_controller
from stillframe.design.coordinates import design_map
from stillframe.estimation.factory import make_estimator
from stillframe.loop.wiring import design_model
from stillframe.middleware import api
from stillframe.plant.frame_plant import make_plant


def per_call_us(call: Callable[[], Any], number: int, repeats: int) -> float:
    """Median over ``repeats`` rounds of the mean time of ``number`` calls, in µs."""
    rounds = []
    for _ in range(repeats):
        started = time.perf_counter_ns()
        for _ in range(number):
            call()
        rounds.append((time.perf_counter_ns() - started) / number * 1e-3)
    return statistics.median(rounds)


def compute_hops(scene: Scene, number: int = 200, repeats: int = 7) -> list[dict[str, Any]]:
    """Rows (node, hop, µs, µs of the rosbags way or None) for everything but DDS; the scene's
    controller's law is timed after its start."""
    plant = make_plant(scene)
    design = design_model(scene)
    estimator = make_estimator(scene, design)
    controller = make_controller(scene, design)
    to_design = design_map(design)
    out, est_out = SensorMessages(scene.sensors), EstimateMessages()
    actuator = actuator_of(scene) or 0
    cmd_out = CommandMessage(actuator)
    sample = plant.sample()
    ns = 1_000_000
    estimate = estimator.step(sample, np.zeros(2))
    while estimate is None:
        plant.advance(np.zeros(2))
        sample = plant.sample()
        estimate = estimator.step(sample, np.zeros(2))
    command = controller.command(sample.t, estimate, sample.force)
    sensor_cdr = [bytes(b) for b in out.cdr(sample, ns)]
    state_cdr, _ = (bytes(b) for b in est_out.cdr(estimate, ns))
    cmd_cdr = bytes(cmd_out.cdr(command, ns))
    sensors = [sensor_reader(ch, scene.sensors) for ch in range(len(SENSOR_TOPICS))]
    state, cmd = estimate_reader(), command_reader(actuator)
    sensor_types = [spec.type_name for spec in SENSOR_TOPICS]
    all_msgs = [*out.fill(sample, ns), out.fill_truth(sample, ns)]
    control = np.zeros(2)

    def time_it(call: Callable[[], Any]) -> float:
        return per_call_us(call, number, repeats)

    started = dataclasses.replace(estimate, t=scene.controller.start + 1.0)   # law active
    fresh = itertools.count(1)
    period = 1.0 / scene.sensors.rate_hz

    def filter_step() -> None:
        """A new sample time each call (the filter skips a stale one)."""
        estimator.step(dataclasses.replace(sample, t=sample.t + next(fresh) * period), control)

    def step_plant() -> None:
        plant.sample()
        plant.advance(control)

    rows = [
        ("sim_node", "plant: sample + advance", time_it(step_plant), None),
        ("sim_node", "serialize 7 sample messages", time_it(lambda: out.cdr(sample, ns)),
         time_it(lambda: [messages.serialize(m) for m in all_msgs])),
        ("estimator_node", "read 5 sensor messages",
         time_it(lambda: [r.read(c) for r, c in zip(sensors, sensor_cdr, strict=False)]),
         time_it(lambda: [messages.deserialize(c, t)
                          for c, t in zip(sensor_cdr, sensor_types, strict=False)])),
        ("estimator_node", f"filter step ({scene.estimator.type})",
         time_it(filter_step), None),
        ("estimator_node", "serialize estimate + covariance",
         time_it(lambda: est_out.cdr(estimate, ns)),
         time_it(lambda: [messages.serialize(m) for m in est_out.fill(estimate, ns)])),
        ("controller_node", "read estimate", time_it(lambda: state.read(state_cdr)),
         time_it(lambda: messages.deserialize(state_cdr, topics.STATE_ESTIMATE.type_name))),
        ("controller_node", f"control law ({scene.controller.type}) + supervisor",
         time_it(lambda: controller.command(started.t, started, sample.force)), None),
        ("controller_node", "design coordinates z = T x", time_it(lambda: to_design @
                                                                   estimate.physical), None),
        ("controller_node", "serialize command", time_it(lambda: cmd_out.cdr(command, ns)),
         time_it(lambda: messages.serialize(cmd_out.fill(command, ns)))),
        ("sim_node", "read command", time_it(lambda: cmd.read(cmd_cdr)),
         time_it(lambda: messages.deserialize(cmd_cdr, COMMAND_TOPICS[actuator].type_name))),
    ]
    return [{"node": n, "hop": h, "us": us, "rosbags_us": rb} for n, h, us, rb in rows]


def dds_hops(scene: Scene, backend: str, number: int = 200,
             repeats: int = 7) -> list[dict[str, Any]]:
    """Writing the seven sample messages and taking them again, in one process on ``backend``
    (no other process involved: the cost of the calls, not of a wake-up)."""
    node = api.create_node(f"_stillframe_hops_{backend}", argv=["hops"], backend=backend)
    try:
        out = SensorMessages(scene.sensors)
        specs = [*SAMPLE_TOPICS, topics.STATE_TRUTH]
        pubs = [node.create_publisher(s.type_name, f"/hops/{s.name}", 100) for s in specs]
        got = [0]

        def count(cdr: bytes, info: Any) -> None:
            got[0] += 1

        for s in specs:
            node.create_subscription(s.type_name, f"/hops/{s.name}", count, 100, raw=True)
        deadline = time.monotonic() + 10.0
        while (min(p.get_subscription_count() for p in pubs) == 0
               and time.monotonic() < deadline):
            node.spin_once(0.05)
        cdrs = out.cdr(out_sample(scene), 1_000_000)

        def write() -> None:
            for pub, cdr in zip(pubs, cdrs, strict=True):
                pub.publish(cdr)

        write_us, read_us = [], []
        for _ in range(repeats):
            for _ in range(number):
                started = time.perf_counter_ns()
                write()
                written = time.perf_counter_ns()
                got[0] = 0
                while got[0] < len(pubs) and api.ok():
                    node.spin_once(0.01)
                write_us.append((written - started) * 1e-3)
                read_us.append((time.perf_counter_ns() - written) * 1e-3)
        return [{"node": f"{backend}", "hop": "write 7 messages", "us": statistics.median(write_us),
                 "rosbags_us": None},
                {"node": f"{backend}", "hop": "wait + take 7 messages (same process)",
                 "us": statistics.median(read_us), "rosbags_us": None}]
    finally:
        node.destroy_node()


def out_sample(scene: Scene) -> Any:
    """The first sample of the scene's plant."""
    return make_plant(scene).sample()
