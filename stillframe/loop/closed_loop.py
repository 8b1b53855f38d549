"""The closed loop in one process, lock-step: plant → estimator → controller → plant.

Per sample period k, exactly what the three nodes do in the DDS lock-step protocol, through the
same :class:`~stillframe.loop.step.LoopStep` as sim_node: the readings stamped t_k
(:meth:`~stillframe.loop.step.LoopStep.sample`), ``estimator.step(sample, actuation applied since
t_k−1)``, ``controller.command(t_k, estimate, measured force)``, the command offered to the step
through its command gate, and the period advanced (with ``actuators.delay_periods`` = d, the
command answering sample k − d). The estimator gets what the actuators applied after their
saturation and slew limits (what the simulator reports in the encoder's ``effort`` and the
floor-3 load cell), not the command, so that a saturated actuator cannot wind the estimate up.
The same scene and seeds therefore give the same numbers here and through the nodes.

With ``adaptation.enabled`` the loop runs the scene's
:class:`~stillframe.loop.adaptation.Adaptation` on the estimator's inputs after each estimator
step, as estimator_node does, and applies each hand-over before the estimator step of its sample.

The evaluation is :func:`stillframe.loop.evaluation.evaluate`.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract.codecs import COMMAND_TOPICS
from stillframe.estimation.base import Filter
from stillframe.loop.adaptation import Adaptation
from stillframe.loop.designs import Handover
from stillframe.loop.energy_balance import EnergyLedger
from stillframe.loop.evaluation import LoopHistory, evaluate, open_loop_truth, plant_report
from stillframe.loop.parts import controller_of, estimator_of, simulator_of
from stillframe.loop.step import LoopStep
from stillframe.loop.wiring import design_model

__all__ = ["LoopHistory", "evaluate", "open_loop_truth", "run_closed_loop"]

Progress = Callable[[float], None]


def run_closed_loop(scene: Scene, progress: Progress | None = None) -> LoopHistory:
    """Run the scene's plant, estimator and controller lock-step for ``scene.duration``."""
    started = time.perf_counter()
    spec, plant = simulator_of(scene)
    step = LoopStep(spec, plant)
    design = design_model(scene)
    estimator = estimator_of(scene, design)
    controller = controller_of(scene, design)
    n = spec.samples
    rows = np.full((n, 20), np.nan)
    control = np.zeros(2)
    ledger = EnergyLedger.of(plant, scene)      # pH plant: balance and passivity check
    adaptation = Adaptation(scene, n) if scene.adaptation.enabled else None
    handover: Handover | None = None
    every = max(1, n // 100)
    looping, looping_cpu = time.perf_counter(), time.process_time()
    for k in range(n):
        sample = step.sample()
        if ledger is not None and sample.truth is not None:   # the pH plant reports its truth
            ledger.update(float(sample.truth[3]))
        if handover is not None and k == handover.sample:
            assert isinstance(estimator, Filter) and controller is not None  # checked: kf, lqg
            estimator = handover.apply(estimator, controller)
            handover = None
        estimate = estimator.step(sample, control) if estimator else None
        if adaptation is not None:
            handover = adaptation.observe(k, sample, control) or handover
        if controller is not None:
            command = controller.command(sample.t, estimate, sample.force)
            step.offer(controller.actuator, float(command.vector[controller.actuator]),
                       step.now_ns)
        period = step.advance()
        rows[k, 0], rows[k, 1:9], rows[k, 17:19], rows[k, 19] = (
            sample.t, sample.truth, period.command, sample.force)
        control = period.applied
        if estimate is not None:
            rows[k, 9:17] = estimate.physical
        if progress and k % every == 0:
            progress(k / n)
    fine_t, floors, velocities = plant.truth_history()
    history = LoopHistory(rows[:, 0], rows[:, 1:9], rows[:, 9:17], rows[:, 17:19], rows[:, 19],
                          fine_t, floors, velocities)
    if controller is not None:
        history.evaluation = evaluate(history, scene)
    done = time.perf_counter()
    history.evaluation.update({
        "steps": n,
        "wall_s": done - started,
        "loop_s": done - looping,   # without the set-up: what sim_node's wall_s counts
        "loop_cpu_s": time.process_time() - looping_cpu,
        "plant": plant_report(plant),
        "structure_events": step.event_records(),
        **step.counts,
        "command_gates": step.gate_reports([spec.name for spec in COMMAND_TOPICS]),
        "estimator": vars(estimator.counters) if estimator else None,
        "controller": vars(controller.counters) if controller else None,
        "controller_compute_s": controller.compute_stats() if controller else None,
    })
    if ledger is not None:
        history.evaluation["energy_balance"] = ledger.values()
    if adaptation is not None:
        history.evaluation["adaptation"] = adaptation.report()
    return history
