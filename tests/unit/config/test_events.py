"""The scene section ``events``: each bad entry is one line naming its key at load (exit code 2
from the command line, before anything runs), and the structure after each event is the scene's
with the changes of the events so far, relative to the scene's own values."""

from __future__ import annotations

import subprocess
import sys

import pytest

from stillframe.config.events import first_sample_at
from stillframe.config.scene import changed_scene, event_changes, load_scene, scene_from_dict
from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT

BASE = {"name": "x", "duration": 10.0}     # 32 Hz: the last sample boundary is 9.96875 s


def scene_with(events: object, **sections: object) -> object:
    return scene_from_dict({**BASE, **sections, "events": events})


ERRORS = [
    ([{"time": 11.0, "floor": 1, "mass": 1.0}], {}, "events[0].time: 11 s is past the run's last"),
    ([{"time": 9.99, "pendulum_mass": 0.1}], {}, "events[0].time: 9.99 s is past"),
    ([{"time": 5.0, "floor": 2, "mass": -1.0}], {}, "events[0].mass: must lie in [1e-06"),
    ([{"time": 5.0, "floor": 2, "mass": 0.0}], {}, "events[0].mass: must lie in [1e-06"),
    ([{"time": 5.0, "pendulum_mass": 0.0}], {}, "events[0].pendulum_mass: must lie in [1e-06"),
    ([{"time": 5.0, "floor": 2, "mass_factor": 0.0}], {}, "events[0].mass_factor: must lie in"),
    ([{"time": 5.0, "story_stiffness": [1.0, -0.2, 1.0]}], {},
     "events[0].story_stiffness: must lie in [0.001, 1000]"),
    ([{"time": 5.0, "story_stiffness": [0.8, 1.0]}], {},
     "events[0].story_stiffness: expected 3 values"),
    ([{"time": 5.0, "pendulum_mass": 0.1}, {"time": 4.0, "pendulum_mass": 0.2}], {},
     "events[1].time: 4 s is before events[0] (5 s)"),
    ([{"time": 5.0, "floor": 4, "mass": 1.0}], {}, "events[0].floor: must lie in [1, 3]"),
    ([{"time": 5.0, "mass": 1.0}], {}, "events[0].mass: needs floor"),
    ([{"time": 5.0, "floor": 2}], {}, "events[0].floor: give one of mass"),
    ([{"time": 5.0, "floor": 2, "mass": 1.0, "mass_factor": 1.3}], {},
     "events[0].floor: give one of mass (the new mass) and mass_factor, got both"),
    ([{"time": 5.0}], {}, "events[0]: changes nothing"),
    ([{"time": 5.0, "youngs_modulus": 1e9}], {}, "events[0].youngs_modulus: unknown key"),
    ([{"time": 5.0, "damping": {"model": "none"}}], {}, "events[0].damping.model: unknown key"),
    ([{"time": 5.0, "damping": {"modal_ratios": [0.02]}}], {},
     "events[0].damping.modal_ratios: the scene's damping.model is rayleigh"),
    ([{"time": 5.0, "damping": {"alpha": 0.5}}], {"damping": {"model": "modal"}},
     "events[0].damping.alpha: the scene's damping.model is modal"),
    ([{"time": 5.0, "pendulum_mass": 0.1}], {"plant": {"model": "file"}},
     "events: plant.model: file is a fixed identified linear model"),
    ([{"time": 5.0, "pendulum_mass": 0.1}], {"model": {"type": "modal"}},
     "events: model.type: modal: events change the lumped and fe plants"),
    ([{"time": 5.0, "pendulum_mass": 0.1}], {"model": {"type": "ph"}},
     "events: model.type: ph"),
    ([{"time": 5.0, "floor": 1, "mass_factor": 1e3}], {"rig": {"floor_masses": [2e4, 1, 1]}},
     "events[0]: the structure after it: rig.floor_masses: must lie in"),
    ({"time": 5.0}, {}, "events: expected a list of mappings"),
    ([{"time": 5.0, "pendulum_mass": 0.1}], {"design": {"after_events": 2}},
     "design.after_events: 2, but the scene has 1 events"),
    ([{"time": 5.0, "pendulum_mass": 0.1}], {"design": {"model": "file", "after_events": 1}},
     "design.after_events: the design is the identified model of design.file"),
    ([{"time": 5.0, "pendulum_mass": 0.1}] * 101, {}, "events: at most 100 events"),
]


@pytest.mark.parametrize(("events", "sections", "message"), ERRORS,
                         ids=[m[:40] for *_, m in ERRORS])
def test_bad_events_name_their_key(events: object, sections: dict, message: str) -> None:
    with pytest.raises(InputError) as info:
        scene_with(events, **sections)
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_a_bad_event_stops_the_command_line_at_load_with_exit_code_2() -> None:
    """One line on stderr, code 2, nothing run: the model refuses the structure after the event
    (Rayleigh damping with a negative ratio on the first mode) when the plant is built, before
    the loop starts."""
    done = subprocess.run(
        [sys.executable, "-m", "stillframe", "closed-loop", "scenes/change_mass_floor2.yaml",
         "--set", "events=[{time: 5, damping: {alpha: -5}}]"],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert "error: events[0]: the structure after it: damping." in lines[0], lines


def test_the_structure_after_each_event_is_relative_to_the_scene() -> None:
    scene = scene_with([
        {"time": 2.0, "floor": 2, "mass_factor": 1.3},
        {"time": 3.0, "story_stiffness": [0.8, 1.0, 1.0], "damping": {"alpha": 0.5}},
        {"time": 4.0, "story_stiffness": [0.9, 1.0, 1.0], "floor": 2, "mass": 2.0},
        {"time": 4.0, "pendulum_mass": 0.1},
    ], rig={"columns": {"stiffness_factors": [0.5, 1.0, 1.0]}})
    assert changed_scene(scene, 0).rig == scene.rig
    one = changed_scene(scene, 1)
    assert one.rig.floor_masses == (1.281, 0.814 * 1.3, 1.380)
    assert one.events == () and one.damping == scene.damping
    two = changed_scene(scene, 2)
    assert two.rig.columns.stiffness_factors == (0.5 * 0.8, 1.0, 1.0)    # of the scene's
    assert two.damping.alpha == 0.5 and two.damping.beta == scene.damping.beta
    three = changed_scene(scene, 3)
    assert three.rig.columns.stiffness_factors == (0.5 * 0.9, 1.0, 1.0)  # not compounded
    assert three.rig.floor_masses[1] == 2.0
    assert three.damping.alpha == 0.5                                     # kept from before
    assert changed_scene(scene, 4).rig.pendulum.mass == 0.1
    assert event_changes(scene, 1) == {"rig.columns.stiffness_factors": [0.4, 1.0, 1.0],
                                 "damping.alpha": 0.5}
    # a changed scene is a scene: written out and read back it is the same
    assert scene_from_dict(three.to_dict()) == three


def test_an_event_applies_at_the_first_sample_boundary_at_or_after_its_time() -> None:
    period = 1 / 32
    assert first_sample_at(60.0, period) == 1920
    assert first_sample_at(60.01, period) == 1921
    assert first_sample_at(0.0, period) == 0
    assert first_sample_at(0.1, 1 / 100) == 10        # 0.1 / 0.01 = 10.000000000000002


def test_shipped_change_scenes_have_a_minute_of_each_structure() -> None:
    for name in ("change_mass_floor2", "change_stiffness_story1"):
        scene = load_scene(REPO_ROOT / "scenes" / f"{name}.yaml")
        (event,) = scene.events
        assert event.time == 60.0 and scene.duration - event.time >= 60.0


def test_the_open_loop_simulation_refuses_events_rather_than_ignore_them() -> None:
    from stillframe.dynamics.simulation import simulate

    scene = scene_with([{"time": 5.0, "pendulum_mass": 0.1}])
    with pytest.raises(InputError, match="events: simulate integrates one structure"):
        simulate(scene)


def test_the_oracle_design_is_the_lumped_model_of_the_structure_after_the_events() -> None:
    """``design.after_events: 1`` designs on the changed structure: its linear model's mass and
    stiffness are those of the thesis's lumped matrices with floor 2's mass times 1.3, assembled
    here from the rig's values (m2 on the diagonal, k_i from the stories)."""
    import numpy as np

    from stillframe.loop.wiring import design_model

    scene = load_scene(REPO_ROOT / "scenes" / "change_mass_floor2.yaml",
                       ["design.after_events=1"])
    before = design_model(load_scene(REPO_ROOT / "scenes" / "change_mass_floor2.yaml"))
    after = design_model(scene).linearized()
    masses = np.array(scene.rig.floor_masses) * [1.0, 1.3, 1.0]
    np.testing.assert_allclose(np.diag(after.mass)[:3] - [0, 0, scene.rig.pendulum.mass],
                               masses, rtol=1e-12)
    np.testing.assert_array_equal(after.stiffness, before.linearized().stiffness)
    assert after.mass[1, 1] != before.linearized().mass[1, 1]
