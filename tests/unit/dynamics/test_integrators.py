"""Integrators: observed order, energy behaviour and agreement with an adaptive reference."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.config.scene import scene_from_dict
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.integrators import (
    NO_SUBDIVISION,
    RK4,
    ImplicitMidpoint,
    IntegrationError,
    Subdivision,
    integrate,
    reference_solution,
)
from stillframe.dynamics.models import build_model
from stillframe.dynamics.simulation import initial_state
from stillframe.dynamics.systems import LinearSystem, MechanicalSystem

# A large pendulum swing makes the lumped model clearly nonlinear.
SWING = ["initial.phi=1.2", "initial.floors=[0.002, 0.003, 0.004]"]


def lumped(extra: list[str] | None = None):
    scene = scene_from_dict({"name": "t"}, [*SWING, *(extra or [])])
    model = build_model(scene)
    return scene, model, MechanicalSystem(model, floor_load(scene.excitation, scene.duration))


def final_error(integrator, system, x0, horizon: float, h: float, exact: np.ndarray) -> float:
    x = integrate(system, x0, h, round(horizon / h), integrator)
    return float(np.max(np.abs(x - exact)) / np.max(np.abs(exact)))


@pytest.mark.parametrize(("integrator", "order", "steps"), [
    (RK4, 4, [4e-3, 2e-3, 1e-3, 5e-4]),
    (ImplicitMidpoint, 2, [2e-3, 1e-3, 5e-4, 2.5e-4]),
])
def test_observed_order_on_the_nonlinear_lumped_model(integrator, order: int,
                                                      steps: list[float]) -> None:
    scene, model, system = lumped()
    x0 = initial_state(model, scene.initial)
    horizon = 0.4
    exact = reference_solution(system, x0, np.array([0.0, horizon]), "dop853", 1e-13, 1e-15)[-1]
    errors = [final_error(integrator(), system, x0, horizon, h, exact) for h in steps]
    slope = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert slope == pytest.approx(order, abs=0.25), (errors, slope)


def test_implicit_midpoint_conserves_the_energy_of_the_linear_undamped_fe_model() -> None:
    scene = scene_from_dict({"name": "t"}, ["model.type=fe", "damping.model=none",
                                            "rig.pendulum.hinge_damping=0"])
    model = build_model(scene)
    system = LinearSystem(model.linearized())
    x0 = initial_state(model, scene_from_dict(
        {"name": "t"}, ["initial.floors=[0.001, -0.002, 0.003]", "initial.phi=0.05"]).initial)
    x0[model.n_dof:] = np.random.default_rng(0).normal(size=model.n_dof) * 1e-3
    e0 = system.energy(x0)
    energies = []
    integrate(system, x0, 1e-3, 100_000, ImplicitMidpoint(),
              observer=lambda k, t, x: energies.append(system.energy(x)) if k % 1000 == 0
              else None)
    drift = np.max(np.abs(np.array(energies) - e0)) / e0
    assert drift < 1e-9


def test_nonlinear_energy_error_is_bounded_and_shrinks_at_second_order() -> None:
    scene, model, system = lumped(["damping.model=none", "rig.pendulum.hinge_damping=0",
                                   "initial.phi=2.5"])
    x0 = initial_state(model, scene.initial)
    e0 = system.energy(x0)

    def max_energy_error(h: float, horizon: float = 3.0) -> tuple[float, float]:
        errors: list[float] = []
        integrate(system, x0, h, round(horizon / h), ImplicitMidpoint(),
                  observer=lambda k, t, x: errors.append(abs(system.energy(x) - e0)))
        half = len(errors) // 2
        return max(errors[:half]), max(errors)

    coarse_first, coarse = max_energy_error(2e-3)
    fine_first, fine = max_energy_error(1e-3)
    # bounded: no secular growth from the first half to the whole run
    assert coarse < 2.0 * coarse_first
    assert fine < 2.0 * fine_first
    # second order: halving the step divides the error by about four
    assert coarse / fine == pytest.approx(4.0, rel=0.15)
    assert coarse / e0 < 1e-3


def test_worst_case_forcing_agrees_with_the_adaptive_reference() -> None:
    """Thesis §5.6 forcing (0.1 N at 1.9, 5.7, 8.8 Hz on floor 1), 10 s, RK4 at 1 ms."""
    scene = scene_from_dict({"name": "t"}, ["excitation.type=harmonics"])
    model = build_model(scene)
    system = MechanicalSystem(model, floor_load(scene.excitation, 10.0))
    x0 = initial_state(model, scene.initial)
    t_eval = np.arange(0, 10001) * 1e-3
    reference = reference_solution(system, x0, t_eval, "dop853", 1e-11, 1e-14)
    states: list[np.ndarray] = []
    integrate(system, x0, 1e-3, 10_000, RK4(), observer=lambda k, t, x: states.append(x))
    floors = np.array(states)[:, :3]
    error = np.max(np.abs(floors - reference[:, :3])) / np.max(np.abs(reference[:, :3]))
    assert error < 1e-4  # measured 1.4e-5: (hω)⁴-sized phase error of the 8.8 Hz mode
    # Radau agrees with DOP853 too (the second adaptive reference)
    radau = reference_solution(system, x0, t_eval[:2001], "radau", 1e-10, 1e-13)
    np.testing.assert_allclose(radau[:, :3], reference[:2001, :3], atol=1e-8)


def test_rk4_beyond_its_stability_limit_fails_with_a_clear_error() -> None:
    scene = scene_from_dict({"name": "t"}, ["model.type=fe", "damping.model=modal",
                                            "initial.floors=[0.001, 0.0, 0.0]"])
    model = build_model(scene)
    system = MechanicalSystem(model)
    bare = RK4()
    bare.subdivision = NO_SUBDIVISION
    with pytest.raises(IntegrationError, match=r"integrator\.dt: the state became non-finite"):
        integrate(system, initial_state(model, scene.initial), 1e-3, 20_000, bare)
    # subdivided, the step needs more than one halving (the limit is 0.361 ms): a floor of
    # dt/2 is reached at the first step and named
    once = RK4()
    once.subdivision = Subdivision(max_halvings=1)
    with pytest.raises(IntegrationError, match=r"integrator\.dt: .* at t = 0 s .* after 1 "
                       r"halvings of the step \(integrator\.max_halvings\)"):
        integrate(system, initial_state(model, scene.initial), 1e-3, 20_000, once)
