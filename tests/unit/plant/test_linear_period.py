"""The linear plant's period as one matrix product (stillframe/plant/linear_period.py).

- ``plant.discretization: substeps`` gives the implicit midpoint integrator's own steps to
  round-off;
- ``zoh`` is exact for the held command: its substep matrices are python-control's ``c2d``
  (zero-order hold) and its state agrees with scipy's DOP853 at tight tolerances, where the
  midpoint substeps are off by 2e-3 after 2 s; the substepped integration converges to it at
  the midpoint rule's order 2.
"""

from __future__ import annotations

import control
import numpy as np
import pytest
import scipy.linalg as sla

from stillframe.dynamics.integrators import ImplicitMidpoint, integrate, reference_solution
from stillframe.errors import InputError
from stillframe.plant.frame_plant import FramePlant
from stillframe.plant.linear_period import zoh_recurrence
from tests.support.scenes import lumped_scene, thesis_scene

QUIET = ["plant.process_noise_std=[0,0,0,0,0,0,0,0]", "duration=2.0", "controller.start=1.0",
         "evaluation.window=0.5"]
TORQUE = 0.01  # N m, held over the run


def plant(*overrides: str) -> FramePlant:
    return FramePlant(thesis_scene("thesis_lqg", [*QUIET, *overrides]))


def run(p: FramePlant, periods: int) -> np.ndarray:
    for _ in range(periods):
        p.advance(np.array([TORQUE, 0.0]))
    return p.x.copy()


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def test_zoh_substep_is_python_controls_c2d() -> None:
    p = plant()
    s = p.system
    A, B = np.linalg.solve(s.E, s.A), np.linalg.solve(s.E, s.B)
    reference = control.c2d(control.ss(A, B, np.eye(s.n), 0), p.h, method="zoh")
    r = zoh_recurrence(s, p.h)
    np.testing.assert_allclose(r.M, reference.A, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.N, reference.B, rtol=0, atol=1e-12 * np.max(np.abs(r.N)))


def test_zoh_is_exact_for_a_held_command_where_midpoint_substeps_are_not() -> None:
    free = "excitation.type=none"
    zoh = run(plant(free, "plant.discretization=zoh"), 64)
    midpoint = plant(free)
    x0 = midpoint.x.copy()
    substepped = run(midpoint, 64)
    midpoint.system.control = np.array([0.0, 0.0, 0.0, TORQUE])
    exact = reference_solution(midpoint.system, x0, np.array([0.0, 2.0]))[-1]
    assert relative(zoh, exact) < 1e-9               # DOP853 at rtol 1e-11
    assert 1e-3 < relative(substepped, exact) < 3e-3  # midpoint at dt = 1/1024 s over 2 s
    # the substepped integration converges to the exact step at order 2: dt / 4 → error / 16
    finer = run(plant(free, "integrator.dt=2.44140625e-4"), 64)
    ratio = relative(substepped, zoh) / relative(finer, zoh)
    assert 15.0 < ratio < 17.0


def test_zoh_with_the_harmonic_load_agrees_with_the_converged_solution() -> None:
    """The force is linear between substeps in the ZOH/FOH step: 7e-5 relative after 2 s of
    the thesis's three harmonics, against 1.3e-3 for the midpoint substeps."""
    zoh_plant = plant("plant.discretization=zoh")
    x0 = zoh_plant.x.copy()
    zoh = run(zoh_plant, 64)
    zoh_plant.system.control = np.array([0.0, 0.0, 0.0, TORQUE])
    exact = reference_solution(zoh_plant.system, x0, np.array([0.0, 2.0]))[-1]
    assert relative(zoh, exact) < 2e-4
    assert relative(zoh, exact) < 0.1 * relative(run(plant(), 64), exact)


def test_batched_midpoint_is_the_integrators_steps_to_round_off() -> None:
    """Both runs take the midpoint step x ↦ M x + c; round-off of γ u max|x| per step (γ = 2n:
    a solve and a product) reaches step k through M^(k−j), so the runs differ by at most
    Σ_k ‖M^k‖₂ · 2n u max|x|, as in test_numerics_any_blas."""
    batched = plant()
    system, x0 = batched.system, batched.x.copy()
    run(batched, 32)
    system.control = np.array([0.0, 0.0, 0.0, TORQUE])
    rows = []
    steps = 32 * batched.substeps
    stepped = integrate(system, x0, batched.h, steps, ImplicitMidpoint(),
                        observer=lambda k, t, x: rows.append(x[batched.physical_index].copy()))
    step = sla.solve(system.E - 0.5 * batched.h * system.A, system.E + 0.5 * batched.h * system.A)
    power, growth = np.eye(len(step)), 0.0
    for _ in range(steps):
        growth += np.linalg.norm(power, 2)
        power = step @ power
    bound = growth * 2 * len(step) * np.finfo(float).eps / 2
    assert bound < 1e-9
    reference = np.array(rows)
    largest = max(np.max(np.abs(reference)), np.max(np.abs(stepped)))
    assert np.max(np.abs(batched.x - stepped)) <= bound * largest
    fine_t, floors, velocities = batched.truth_history()
    np.testing.assert_allclose(floors, reference[:, :3], rtol=0, atol=bound * largest)
    np.testing.assert_allclose(velocities, reference[:, 4:7], rtol=0, atol=bound * largest)
    np.testing.assert_array_equal(fine_t, np.arange(len(rows)) * batched.h)


def test_sampled_accelerations_are_the_derivative_to_round_off() -> None:
    p = plant("sensors.accelerometer_noise_std=0")
    run(p, 10)
    exact = sla.solve(p.system.E, p.system.rhs(p.t, p.x))[p.n_dof:][p.model.floor_index]
    # (E⁻¹A)x against E⁻¹(Ax): a few u times the sum of the terms' sizes, the accelerations'
    # scale; an acceleration near zero keeps that absolute error
    np.testing.assert_allclose(p.sample().measurements[:3], exact, rtol=1e-12,
                               atol=1e-13 * np.abs(exact).max())


def test_zoh_needs_the_linear_plant() -> None:
    with pytest.raises(InputError, match=r"plant\.discretization: zoh needs the linear plant"):
        FramePlant(lumped_scene(["plant.discretization=zoh"]))
