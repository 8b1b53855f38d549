"""Structure events on the lumped and FE plants (scene ``events``): the plant changes at the first
sample boundary at or after each event, from the state it is in, and then runs as a plant built
from the changed scene; the changed structure's frequencies are the closed form's."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg as sla

from stillframe.config.scene import Scene, changed_scene, load_scene, scene_from_dict
from stillframe.dynamics.models import build_model
from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.loop.spec import LoopSpec
from stillframe.loop.step import LoopStep
from stillframe.plant.frame_plant import FramePlant
from tests.support.scenes import characteristic_frequencies

CHANGE_SCENES = ("change_mass_floor2", "change_stiffness_story1")
#: every kind of change at once: a floor's mass, the stories' stiffness, the damping, the
#: pendulum's mass (the nonlinear coupling m4 L4 cos φ and the gravity torque change with it)
EVERYTHING = {"time": 0.5, "floor": 2, "mass_factor": 1.3, "story_stiffness": [0.8, 1.1, 1.0],
              "pendulum_mass": 0.1}


def free_scene(model: str, method: str, event: dict, damping: dict) -> Scene:
    """A free response (no force, no noise, no controller) from a displaced state with the
    pendulum swinging, 32 Hz samples, an event at 0.5 s (sample 16)."""
    return scene_from_dict({
        "name": "free", "duration": 1.5,
        "model": {"type": model, "elements_per_column": 4},
        "damping": damping,
        "integrator": {"method": method, "dt": 1 / 1024},
        "initial": {"floors": [1e-3, 2e-3, 3e-3], "phi": 0.3, "floor_velocities": [0, 1e-2, 0]},
        "controller": {"type": "none"}, "estimator": {"type": "none"},
        "events": [event]})


def run_samples(step: LoopStep, n: int) -> None:
    for _ in range(n):
        step.sample()
        step.advance()


CASES = [
    ("lumped", "rk4", {**EVERYTHING, "damping": {"alpha": 0.5, "beta": -1e-4}},
     {"model": "rayleigh"}),
    ("lumped", "midpoint", EVERYTHING, {"model": "rayleigh"}),
    ("fe", "rk4", {**EVERYTHING, "damping": {"modal_ratios": [0.05, 0.01]}}, {"model": "modal"}),
    ("fe", "midpoint", {**EVERYTHING, "damping": {"high_mode_ratio": 0.01}}, {"model": "modal"}),
]


@pytest.mark.parametrize(("model", "method", "event", "damping"), CASES,
                         ids=[f"{m}-{i}" for m, i, *_ in CASES])
def test_after_the_event_the_plant_is_the_changed_scenes_plant_from_the_same_state(
        model: str, method: str, event: dict, damping: dict) -> None:
    """Bit for bit: both run the same arithmetic (the changed model built from the changed scene,
    a fresh integrator, the same compiled kernels, warmed up at load or not) from the same state
    and time. And not the unchanged plant's response: the change took effect."""
    scene = free_scene(model, method, event, damping)
    spec = LoopSpec.of(scene)
    (scheduled,) = spec.events
    assert scheduled.sample == 16
    plant = FramePlant(scene)
    plant.warm_up()      # as sim_node does: the kernels of the changed structure too
    step = LoopStep(spec, plant)
    unchanged = FramePlant(dataclasses.replace(scene, events=()))
    run_samples(step, 16)
    for _ in range(16):
        unchanged.advance(np.zeros(2))
    np.testing.assert_array_equal(step.plant.x, unchanged.x)   # same up to the boundary
    assert step.applied_events == []
    at_boundary = step.plant.x.copy()
    changed = FramePlant(changed_scene(scene, 1))
    changed.x, changed.k = at_boundary.copy(), 16
    got = step.sample()                              # sample 16: the event applies first
    assert step.changed == (scheduled,) and step.applied_events == [scheduled]
    np.testing.assert_array_equal(step.plant.x, at_boundary)   # the state carried over
    # its readings are the changed structure's accelerations
    np.testing.assert_array_equal(got.measurements, changed.sample().measurements)
    assert not np.array_equal(got.measurements, unchanged.sample().measurements)
    step.advance()
    changed.advance(np.zeros(2))
    unchanged.advance(np.zeros(2))
    run_samples(step, spec.samples - 17)
    for _ in range(spec.samples - 17):
        changed.advance(np.zeros(2))
        unchanged.advance(np.zeros(2))
    after = step.plant.truth_history()
    reference = changed.truth_history()
    rows = len(reference[0]) - 1          # the changed plant's rows after its first (the state)
    for got, want in zip(after, reference, strict=True):
        np.testing.assert_array_equal(got[-rows:], want[1:])
    np.testing.assert_array_equal(step.plant.x, changed.x)
    assert np.max(np.abs(step.plant.x - unchanged.x)) > 1e-4 * np.max(np.abs(unchanged.x))


def test_the_structure_changes_only_at_its_event() -> None:
    """Two events between boundaries and one on a boundary: each at the first boundary at or
    after its time, in order; nothing before."""
    scene = free_scene("lumped", "rk4", {"time": 0.51, "floor": 1, "mass_factor": 1.1},
                       {"model": "rayleigh"})
    scene = dataclasses.replace(scene, events=(
        *scene.events, dataclasses.replace(scene.events[0], time=0.52, mass_factor=1.2),
        dataclasses.replace(scene.events[0], time=1.0, floor=3, mass_factor=0.9)))
    spec = LoopSpec.of(scene)
    assert [e.sample for e in spec.events] == [17, 17, 32]
    step = LoopStep(spec, FramePlant(scene))
    seen = []
    for _ in range(spec.samples):
        step.sample()
        seen.append((step.k, [e.index for e in step.changed]))
        step.advance()
    assert [s for s in seen if s[1]] == [(17, [0, 1]), (32, [2])]
    assert step.plant.model.structure.mass[0, 0] == pytest.approx(1.281 * 1.2, rel=1e-15)
    assert step.plant.model.structure.mass[2, 2] == pytest.approx(1.380 * 0.9, rel=1e-15)
    assert [r["applied_s"] for r in step.event_records()] == [17 / 32, 17 / 32, 1.0]


@pytest.mark.parametrize("name", CHANGE_SCENES)
def test_the_changed_frequencies_are_the_closed_forms(name: str) -> None:
    """``stillframe modes`` of a shipped change scene: its frequencies after the event, and
    those of the model the plant takes at the event, against the characteristic polynomial of
    the changed rig. Tolerance 1e-12: both solve well-separated simple roots to a few units of
    round-off (Brent's to 4 ε in λ, half that in ω); a 30 % mass or 20 % stiffness change moves
    the frequencies by 1e-4 to 1e-1."""
    scene = load_scene(REPO_ROOT / "scenes" / f"{name}.yaml")
    done = subprocess.run([sys.executable, "-m", "stillframe", "modes", f"scenes/{name}.yaml",
                           "--json"], capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    table = json.loads(done.stdout)
    (after,) = table["after_events"]
    changed = changed_scene(scene, 1)
    expected = characteristic_frequencies(changed)
    np.testing.assert_allclose(after["frequencies_hz"], expected, rtol=1e-12)
    np.testing.assert_allclose(table["frequencies_hz"], characteristic_frequencies(scene),
                               rtol=1e-12)
    # the structure moved: every floor mode by more than the tolerance, and downward (a mass
    # added or a stiffness lost lowers every Rayleigh quotient)
    before = np.array(table["frequencies_hz"])
    assert np.all(np.array(after["frequencies_hz"])[1:] < before[1:] * (1 - 1e-4))
    plant = FramePlant(scene)
    plant.change_structure(0)
    np.testing.assert_array_equal(plant.model.linearized().stiffness,
                                  build_model(changed).linearized().stiffness)
    np.testing.assert_array_equal(plant.model.linearized().mass,
                                  build_model(changed).linearized().mass)


def test_a_stiffness_factor_on_every_fe_story_scales_the_frames_frequencies_by_its_root() -> None:
    """The FE structure (the pendulum apart): K → f K with M unchanged gives ω → √f ω exactly.
    Its three floor modes, from the inverse problem M ψ = μ K ψ (accurate relative to the
    largest μ, the lowest mode), to 1e-12 relative."""
    sets = ["model.type=fe", "model.elements_per_column=6", "damping.model=none"]

    def floor_modes(extra: list[str]) -> np.ndarray:
        s = build_model(scene_from_dict({"name": "x"}, [*sets, *extra])).structure
        return 1 / np.sqrt(sla.eigh(s.mass, s.stiffness, eigvals_only=True)[::-1][:3])

    scaled = floor_modes(["rig.columns.stiffness_factors=[0.64, 0.64, 0.64]"])
    np.testing.assert_allclose(scaled, 0.8 * floor_modes([]), rtol=1e-12)


def test_the_one_process_loop_reports_the_event_and_its_uncontrolled_baseline_has_it() -> None:
    """A shipped change scene shortened around its event: the result says when the change was
    applied; the open-loop baseline (evaluation.baseline: open_loop) is run through the same
    step, so its plant changes at the same sample (its peaks after the change differ from those
    of the scene without the event)."""
    sets = ["duration=4", "controller.start=2", "evaluation.window=1", "events=[{time: 2.5, "
            "floor: 2, mass_factor: 1.3}]"]
    scene = load_scene(REPO_ROOT / "scenes" / "change_mass_floor2.yaml", sets)
    history = run_closed_loop(scene)
    assert history.evaluation["structure_events"] == [
        {"event": 0, "time_s": 2.5, "applied_s": 2.5, "sample": 80,
         "changes": {"rig.floor_masses": [1.281, 0.814 * 1.3, 1.38]}}]
    without = run_closed_loop(dataclasses.replace(scene, events=()))
    assert without.evaluation["structure_events"] == []
    assert (history.evaluation["peak_uncontrolled"]
            != without.evaluation["peak_uncontrolled"])
    np.testing.assert_array_equal(history.truth[:81], without.truth[:81])
    assert not np.array_equal(history.truth[81:], without.truth[81:])
