"""The loop's record and its evaluation (the thesis's "percentage decrease of the maximum
amplitude at steady state", eq. 5.233, 5.287): the peak of |x_i| and |ẋ_i| over the last
``evaluation.window`` seconds of the run (with control) against the uncontrolled peak, from the
true state at every integrator step; reduction = 100 (1 − controlled / uncontrolled) %. The
uncontrolled peak is taken over the window before ``controller.start`` in the same run
(``evaluation.baseline: before_start``, the thesis) or over the same last window of a second run
with the controller off and the same seeds (``open_loop``), which is not fooled by a response
still settling or beating at the start.

The one-process loop (:mod:`stillframe.loop.closed_loop`) and sim_node evaluate their runs here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from stillframe.config.scene import Scene
from stillframe.loop.spec import LoopSpec
from stillframe.loop.step import LoopStep
from stillframe.plant.frame_plant import make_plant
from stillframe.plant.protocol import Plant

__all__ = ["LoopHistory", "evaluate", "open_loop_truth", "plant_report", "reduction_pct",
           "steady_state_peaks"]


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
    """The reduction of each peak in percent, 100 (1 − controlled / uncontrolled), element by
    element."""
    return (100.0 * (1.0 - controlled / uncontrolled)).tolist()


def open_loop_truth(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plant's fine truth history with no command (same scene and seeds), through the
    loop's step (so that the scene's structure events apply at the same samples)."""
    spec, plant = LoopSpec.of(scene), make_plant(scene)
    step = LoopStep(spec, plant)
    for _ in range(spec.samples):
        step.sample()
        step.advance()
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


def plant_report(plant: Plant) -> dict:
    """What the result says of the plant: model, integrator, step, the commands its actuators
    changed, the integrator steps halved (:mod:`stillframe.dynamics.integrators`; the pH plant
    takes its own steps and halves none)."""
    return {"model": plant.model.name, "integrator": plant.integrator.name, "dt": plant.h,
            "actuator_limited": plant.actuators.limited,
            "subdivisions": getattr(plant, "subdivisions", 0)}
