"""The closed loop in one process, lock-step: plant → estimator → controller → plant.

Per sample period k, exactly what the three nodes do in the DDS lock-step protocol:
``Plant.sample`` (readings stamped t_k), ``estimator.step(sample, actuation applied since t_k−1)``,
``controller.command(t_k, estimate, measured force)``, ``Plant.advance(command)`` (with
``actuators.delay_periods`` = d, the command answering sample k − d:
:class:`~stillframe.plant.actuation_delay.ActuationDelay`). The estimator
gets what the actuators applied after their saturation and slew limits (what the simulator reports
in the encoder's ``effort`` and the floor-3 load cell), not the command, so that a saturated
actuator cannot wind the estimate up. The same scene
and seeds therefore give the same numbers here and through the nodes.

Evaluation (the thesis's "percentage decrease of the maximum amplitude at steady state",
eq. 5.233, 5.287): the peak of |x_i| and |ẋ_i| over the last ``evaluation.window`` seconds of the
run (with control) against the uncontrolled peak, from the true state at every integrator step;
reduction = 100 (1 − controlled / uncontrolled) %. The uncontrolled peak is taken over the window
before ``controller.start`` in the same run (``evaluation.baseline: before_start``, the thesis) or
over the same last window of a second run with the controller off and the same seeds
(``open_loop``), which is not fooled by a response still settling or beating at the start.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract.signals import Command
from stillframe.control.factory import make_controller
from stillframe.estimation.factory import make_estimator
from stillframe.loop.energy_balance import EnergyLedger
from stillframe.loop.wiring import design_model
from stillframe.plant.actuation_delay import ActuationDelay
from stillframe.plant.frame_plant import Plant, make_plant
from stillframe.plant.ph_plant import PHPlant

Progress = Callable[[float], None]


@dataclass
class LoopHistory:
    """Per sample: times, true and estimated physical state (N×8), the [torque, force]
    commanded for the period (N×2; with an actuation delay, the command sent d periods
    earlier), the load-cell reading; at every integrator step: true floor motion."""

    t: np.ndarray
    truth: np.ndarray
    estimate: np.ndarray
    command: np.ndarray
    force: np.ndarray
    fine_t: np.ndarray
    fine_floors: np.ndarray
    fine_velocities: np.ndarray
    evaluation: dict = field(default_factory=dict)


def steady_state_peaks(t: np.ndarray, values: np.ndarray, start: float, end: float,
                       window: float) -> tuple[np.ndarray, np.ndarray]:
    """max |values| over [start − window, start) and over [end − window, end], per column."""
    eps = 1e-9
    before = (t >= start - window - eps) & (t < start - eps)
    after = (t >= end - window - eps) & (t <= end + eps)
    return np.max(np.abs(values[before]), axis=0), np.max(np.abs(values[after]), axis=0)


def reduction_pct(uncontrolled: np.ndarray, controlled: np.ndarray) -> list[float]:
    return (100.0 * (1.0 - controlled / uncontrolled)).tolist()


def open_loop_truth(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plant's fine truth history with no command (same scene and seeds)."""
    plant = make_plant(scene)
    for _ in range(round(scene.duration / plant.period)):
        plant.advance(np.zeros(2))
    return plant.truth_history()


def evaluate(history: LoopHistory, scene: Scene) -> dict:
    """Steady-state peaks with and without control and their reductions (module docstring)."""
    start, end, window = scene.controller.start, history.fine_t[-1], scene.evaluation.window
    d0, d1 = steady_state_peaks(history.fine_t, history.fine_floors, start, end, window)
    v0, v1 = steady_state_peaks(history.fine_t, history.fine_velocities, start, end, window)
    if scene.evaluation.baseline == "open_loop":
        t, floors, velocities = open_loop_truth(scene)
        d0 = steady_state_peaks(t, floors, end, end, window)[1]
        v0 = steady_state_peaks(t, velocities, end, end, window)[1]
    return {
        "baseline": scene.evaluation.baseline,
        "reduction_pct": {"displacement": reduction_pct(d0, d1), "velocity": reduction_pct(v0, v1)},
        "peak_uncontrolled": {"displacement": d0.tolist(), "velocity": v0.tolist()},
        "peak_controlled": {"displacement": d1.tolist(), "velocity": v1.tolist()},
        "peak_command": float(np.max(np.abs(history.command))),
    }


def plant_report(plant: Plant | PHPlant) -> dict:
    """What the result says of the plant: model, integrator, step, the commands its actuators
    changed, the integrator steps halved (:mod:`stillframe.dynamics.integrators`; the pH plant
    takes its own steps and halves none)."""
    return {"model": plant.model.name, "integrator": plant.integrator.name, "dt": plant.h,
            "actuator_limited": plant.actuators.limited,
            "subdivisions": getattr(plant, "subdivisions", 0)}


def run_closed_loop(scene: Scene, progress: Progress | None = None) -> LoopHistory:
    """Run the scene's plant, estimator and controller lock-step for ``scene.duration``."""
    started = time.perf_counter()
    plant = make_plant(scene)
    design = design_model(scene)
    estimator = make_estimator(scene, design) if scene.estimator.type != "none" else None
    controller = make_controller(scene, design) if scene.controller.type != "none" else None
    n = round(scene.duration / plant.period)
    rows = np.full((n, 20), np.nan)
    control = np.zeros(2)
    delay = ActuationDelay(scene.actuators.delay_periods)
    ledger = EnergyLedger.of(plant, scene)      # pH plant: balance and passivity check
    every = max(1, n // 100)
    looping, looping_cpu = time.perf_counter(), time.process_time()
    for k in range(n):
        sample = plant.sample()
        if ledger is not None and sample.truth is not None:   # the pH plant reports its truth
            ledger.update(float(sample.truth[3]))
        estimate = estimator.step(sample, control) if estimator else None
        command = (controller.command(sample.t, estimate, sample.force) if controller
                   else Command(sample.t))
        delay.put(k, command.vector)
        due = delay.due(k)[0]               # the command of this period (d = 0: this one)
        applied = plant.advance(due)
        rows[k, 0], rows[k, 1:9], rows[k, 17:19], rows[k, 19] = (
            sample.t, sample.truth, due, sample.force)
        control = applied
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
        "estimator": vars(estimator.counters) if estimator else None,
        "controller": vars(controller.counters) if controller else None,
        "controller_compute_s": controller.compute_stats() if controller else None,
    })
    if ledger is not None:
        history.evaluation["energy_balance"] = ledger.values()
    return history
