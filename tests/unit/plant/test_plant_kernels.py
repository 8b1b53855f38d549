"""The nonlinear plant's substeps on the compiled kernels give the numpy integrators' numbers
(stillframe/dynamics/integrators.py, the independent implementation) to round-off, for RK4 on
the lumped model and the implicit midpoint rule on the FE model, with a command held.

RK4: the same operations in the same order, so a few ulps per step (1e-11 relative leaves
room). Midpoint: two simplified-Newton solvers, each stopping when its correction is below
``tol·(1 + max|x|)`` and contracting by ≥ 10 per iteration, so each lies within that of the
step's solution; the damped step map does not amplify, so n steps differ by ≤ 2n·tol·(1 + max|x|)
(a stall is accepted only at the residual's round-off floor, below that).
"""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.dynamics.integrators import ImplicitMidpoint
from stillframe.plant.frame_plant import FramePlant
from tests.support.scenes import lumped_scene


@pytest.mark.parametrize("overrides", [
    [],
    ["model.type=fe", "damping.model=modal", "integrator.method=midpoint",
     "integrator.dt=9.765625e-4"],
], ids=["lumped-rk4", "fe3-midpoint"])
def test_compiled_substeps_equal_the_integrators(overrides: list[str]) -> None:
    scene = lumped_scene(["initial.phi=0.05", *overrides])
    compiled, stepped = FramePlant(scene), FramePlant(scene)
    assert compiled.compiled is not None
    stepped.compiled = None                      # the numpy integrator's path
    for k in range(32):
        command = np.array([0.02 * np.sin(0.3 * k), 0.0])
        compiled.advance(command)
        stepped.advance(command)
    scale = np.max(np.abs(stepped.x))
    newton = 2 * 32 * compiled.substeps * ImplicitMidpoint().tol * (1 + scale)
    assert newton < 1e-6 * scale

    def bound(b: np.ndarray) -> float:
        return newton if "integrator.method=midpoint" in overrides else 1e-11 * np.max(np.abs(b))

    np.testing.assert_allclose(compiled.x, stepped.x, rtol=0, atol=bound(stepped.x))
    for a, b in zip(compiled.truth_history(), stepped.truth_history(), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=bound(b))
    assert np.max(np.abs(stepped.x)) > 1e-3      # the run moved


def test_warm_up_leaves_the_trajectory_as_it_was() -> None:
    """``warm_up`` (the kernels loaded before the loop) changes nothing: the same samples and
    states, bit for bit, as a plant that was not warmed up."""
    scene = lumped_scene(["initial.phi=0.05", "sensors.accelerometer_noise_std=0.01"])
    warmed, cold = FramePlant(scene), FramePlant(scene)
    warmed.warm_up()
    np.testing.assert_array_equal(warmed.x, cold.x)
    for k in range(16):
        a, b = warmed.sample(), cold.sample()
        np.testing.assert_array_equal(a.measurements, b.measurements)
        command = np.array([0.02 * np.sin(0.3 * k), 0.0])
        warmed.advance(command)
        cold.advance(command)
    np.testing.assert_array_equal(warmed.x, cold.x)
    for a, b in zip(warmed.truth_history(), cold.truth_history(), strict=True):
        np.testing.assert_array_equal(a, b)
