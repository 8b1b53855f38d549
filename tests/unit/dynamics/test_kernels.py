"""Compiled kernels against the numpy reference paths (systems + integrators) to round-off."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.config.scene import scene_from_dict
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.integrators import (
    NO_SUBDIVISION,
    RK4,
    ImplicitMidpoint,
    Subdivision,
    integrate,
)
from stillframe.dynamics.kernels import CompiledFrame, banded_order, bandwidth
from stillframe.dynamics.models import build_model
from stillframe.dynamics.simulation import initial_state, simulate
from stillframe.dynamics.systems import MechanicalSystem
from stillframe.errors import IntegrationError

CASES = {
    "lumped-harmonics-swing": ["excitation.type=harmonics", "initial.phi=1.2"],
    "fe3-hammer": ["model.type=fe", "damping.model=modal", "excitation.type=hammer",
                   "excitation.time=0.002", "initial.phi=0.8"],
    "modal5-chirp": ["model.type=modal", "model.elements_per_column=6", "model.modes=5",
                     "damping.model=modal", "excitation.type=chirp", "excitation.amplitude=2"],
    "lumped-none-rotation": ["initial.phi_rate=30", "initial.floors=[0.001, 0, -0.002]"],
}


def _reference(overrides: list[str], integrator, h: float, n: int):
    scene = scene_from_dict({"name": "t"}, overrides)
    model = build_model(scene)
    load = floor_load(scene.excitation, 1.0)
    system = MechanicalSystem(model, load)
    system.control[:] = [0.0, 0.0, 0.01, -0.002]  # held floor-3 force and hinge torque
    x0 = initial_state(model, scene.initial)
    states: list[np.ndarray] = []
    integrate(system, x0, h, n, integrator, observer=lambda k, t, x: states.append(x.copy()))
    return model, load, x0, system.control.copy(), np.array(states)


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize(("method", "integrator"), [("rk4", RK4), ("midpoint", ImplicitMidpoint)])
def test_compiled_kernels_agree_with_the_numpy_integrators(case: str, method: str,
                                                           integrator) -> None:
    h = 1e-4 if method == "rk4" and "lumped" in case else 2e-6 if method == "rk4" else 1e-3
    model, load, x0, control, expected = _reference(CASES[case], integrator(), h, 300)
    states = CompiledFrame(model).run(method, x0, h, 300, load=load, control=control)
    scale = np.max(np.abs(expected), axis=0) + 1e-300
    error = np.max(np.abs(states - expected) / scale)
    # RK4: the same operations, so round-off only; midpoint: both Newton solves stop at 1e-12
    assert error < (1e-12 if method == "rk4" else 1e-9), error


def test_generic_midpoint_on_the_40_element_mesh_stops_at_round_off_and_agrees() -> None:
    """The FE 40 residual cannot resolve a relative 1e-12 (h‖K‖ ~ 1e8): the generic Newton
    accepts a stalled iterate below 1e-9 instead of failing, and agrees with the compiled
    kernel (whose pendulum Newton is scalar and well conditioned)."""
    overrides = ["model.type=fe", "model.elements_per_column=40", "damping.model=modal",
                 "excitation.type=harmonics", "initial.phi=0.3"]
    model, load, x0, control, expected = _reference(overrides, ImplicitMidpoint(), 1e-3, 300)
    states = CompiledFrame(model).run("midpoint", x0, 1e-3, 300, load=load, control=control)
    scale = np.max(np.abs(expected), axis=0) + 1e-300
    error = np.max(np.abs(states - expected) / scale)
    print(f"FE 40, generic vs compiled midpoint: {error:.2g}")
    assert error < 1e-6


def test_fe_dofs_reordered_by_height_are_banded_with_a_constant_bandwidth() -> None:
    """The banded order makes the step matrix banded with half-bandwidth at most 4 for any mesh (two
    nodal DOFs per node, neighbours only): a step costs O(n)."""
    for n_e in (2, 10, 40):
        model = build_model(scene_from_dict({"name": "t"}, [
            "model.type=fe", f"model.elements_per_column={n_e}", "damping.model=modal"]))
        o = banded_order(model)
        s = model.structure
        assert sorted(o) == list(range(s.n_dof))
        assert bandwidth(s.stiffness[np.ix_(o, o)]) <= 4
        assert bandwidth(s.mass[np.ix_(o, o)]) <= 4
        assert bandwidth(s.stiffness) > 3 * n_e  # the natural order is not banded


def test_stride_and_chunks_give_the_same_states() -> None:
    model, load, x0, control, expected = _reference(CASES["fe3-hammer"], ImplicitMidpoint(),
                                                    1e-3, 40)
    frame = CompiledFrame(model)
    whole = frame.run("midpoint", x0, 1e-3, 40, load=load, control=control)
    # against the generic midpoint: the two Newton iterations stop at their own tolerances
    np.testing.assert_allclose(whole, expected, rtol=1e-9, atol=1e-9 * np.max(np.abs(expected)))
    # the stride only leaves states out: the same arithmetic, the same states
    every_tenth = frame.run("midpoint", x0, 1e-3, 40, load=load, control=control, stride=10)
    np.testing.assert_array_equal(every_tenth, whole[::10])
    # two chunks: the same steps but for the load's time, t0 + k dt against (25 + k) dt, which
    # may differ in the last bit and moves the states by round-off of their size
    first = frame.run("midpoint", x0, 1e-3, 25, load=load, control=control)
    rest = frame.run("midpoint", first[-1], 1e-3, 15, load=load, control=control, t0=25e-3)
    np.testing.assert_allclose(rest[-1], whole[-1], rtol=0,
                               atol=1e-12 * np.max(np.abs(whole)))


def test_compiled_rk4_beyond_its_stability_limit_fails_with_a_clear_error() -> None:
    scene = scene_from_dict({"name": "t"}, ["model.type=fe", "damping.model=modal",
                                            "initial.floors=[0.001, 0.0, 0.0]"])
    model = build_model(scene)
    x0 = initial_state(model, scene.initial)
    with pytest.raises(IntegrationError, match=r"integrator\.dt: the state became non-finite"):
        CompiledFrame(model, NO_SUBDIVISION).run("rk4", x0, 1e-3, 20_000)
    with pytest.raises(IntegrationError, match=r"integrator\.dt: .* at t = 0 s .* after 1 "
                       r"halvings of the step \(integrator\.max_halvings\)"):
        CompiledFrame(model, Subdivision(max_halvings=1)).run("rk4", x0, 1e-3, 20_000)


def test_simulate_uses_the_compiled_path_and_matches_the_generic_one() -> None:
    scene = scene_from_dict({"name": "t"}, ["excitation.type=harmonics", "duration=0.5"])
    fast = simulate(scene)
    assert fast.meta["compiled"] is True
    noise = scene_from_dict({"name": "t"}, ["excitation.type=white_noise", "duration=0.05"])
    assert simulate(noise).meta["compiled"] is False  # sampled noise has no compiled form
    model = build_model(scene)
    system = MechanicalSystem(model, floor_load(scene.excitation, 0.5))
    floors: list[np.ndarray] = []
    integrate(system, initial_state(model, scene.initial), 1e-3, 500, RK4(),
              observer=lambda k, t, x: floors.append(x[:3].copy()))
    np.testing.assert_allclose(fast.floors, np.array(floors), rtol=0, atol=1e-15)
