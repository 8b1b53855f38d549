"""The nonlinear plant's substeps on the compiled kernels give the numpy integrators' numbers
(stillframe/dynamics/integrators.py, the independent implementation) to round-off, for RK4 on
the lumped model and the implicit midpoint rule on the FE model, with a command held: measured
1e-16 (RK4) and 8e-14 (midpoint, Newton to 1e-12) relative after one second, asserted to 1e-11.
"""

from __future__ import annotations

import numpy as np
import pytest

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
    np.testing.assert_allclose(compiled.x, stepped.x, rtol=0, atol=1e-11 * scale)
    for a, b in zip(compiled.truth_history(), stepped.truth_history(), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-11 * np.max(np.abs(b)))
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
