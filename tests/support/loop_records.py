"""The records an adaptation reads, taken from the one-process loop of a scene: per sample the
load cell, the torque applied over the period before, and [a1, a2, a3, φ]."""

from __future__ import annotations

import numpy as np

from stillframe.config.scene import Scene
from stillframe.loop.parts import controller_of, estimator_of, simulator_of
from stillframe.loop.step import LoopStep
from stillframe.loop.wiring import design_model


def loop_records(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``t (N,)``, ``u (N, 2)`` = [force, applied torque], ``y (N, 4)`` of the scene's loop."""
    spec, plant = simulator_of(scene)
    step = LoopStep(spec, plant)
    design = design_model(scene)
    estimator, controller = estimator_of(scene, design), controller_of(scene, design)
    assert estimator is not None and controller is not None
    n = spec.samples
    t, u, y = np.zeros(n), np.zeros((n, 2)), np.zeros((n, 4))
    applied = np.zeros(2)
    for k in range(n):
        sample = step.sample()
        estimate = estimator.step(sample, applied)
        command = controller.command(sample.t, estimate, sample.force)
        step.offer(controller.actuator, float(command.vector[controller.actuator]), step.now_ns)
        t[k], u[k], y[k] = sample.t, (sample.force, applied[0]), sample.measurements
        applied = step.advance().applied
    return t, u, y
