"""The adaptation of :mod:`stillframe.loop.adaptation`: the design check against python-control
(dlqr, dlqe), a design that cannot be made refused, the hand-over's state carried over, bad
settings refused before anything runs, and the one-process adaptive run of each shipped change
scene: detection within 15 s, frequencies within 1 % of the true changed model's, the
hand-over before the evaluation window."""

from __future__ import annotations

import subprocess
import sys

import control
import numpy as np
import pytest

from stillframe.config.scene import changed_scene
from stillframe.control.lqg import state_weight
from stillframe.design.identified import storeys, storeys_frame
from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.loop.designs import Handover, check_adaptation, check_design
from stillframe.loop.parts import check_loop
from stillframe.loop.wiring import design_model
from tests.support.scenes import characteristic_frequencies, thesis_scene

CHANGE_SCENES = ("change_mass_floor2", "change_stiffness_story1")


def test_the_design_check_gives_python_controls_gain_and_poles() -> None:
    """On the true model after the mass change: the LQR gain and the regulator's poles are
    python-control's ``dlqr`` on the same ZOH model and weights, the filter's error poles
    ``dlqe``'s eig(Φ − L C) (the current-estimate filter's eig((I − L C) Φ) is the same
    spectrum). Tolerances: two Riccati solvers agree to ~1e-8 relative here."""
    scene = thesis_scene("change_mass_floor2", ["design.after_events=1"])
    design = design_model(scene)
    estimator, controller, check = check_design(scene, design)
    lqr = controller.law.design
    Q = state_weight(design, scene.controller.state_weights)
    K, _, poles = control.dlqr(lqr.A, lqr.B, Q, np.array([[scene.controller.input_weight]]))
    np.testing.assert_allclose(check.gain, K, rtol=1e-6)
    np.testing.assert_allclose(np.sort_complex(check.regulator_poles), np.sort_complex(poles),
                               rtol=1e-7, atol=1e-9)
    phi = estimator.discrete(1 / 32).phi
    _, _, filter_poles = control.dlqe(phi, np.eye(phi.shape[0]), estimator.C, estimator.Q,
                                      estimator.R)
    np.testing.assert_allclose(np.sort_complex(check.estimator_poles),
                               np.sort_complex(filter_poles), rtol=1e-7, atol=1e-9)
    assert check.record()["largest_pole"] < 1.0


def test_a_design_that_cannot_stabilise_the_loop_is_refused() -> None:
    """Storeys whose floor 1 stands apart from the others on a negative stiffness: unstable and
    unreachable from the pendulum's torque, so no LQR stabilises it; the check names it."""
    scene = thesis_scene("change_mass_floor2")
    stiffness = np.diag([-100.0, 2000.0, 1000.0])
    stiffness[1, 2] = stiffness[2, 1] = -900.0
    bad = storeys(np.diag([1.3, 1.0, 1.4]), stiffness, np.eye(3) * 0.5, "a bad identification")
    with pytest.raises(InputError, match=r"not stabilisable|not stable"):
        check_design(scene, storeys_frame(bad, scene.rig))


def test_the_hand_over_carries_the_estimate_and_swaps_the_law_only() -> None:
    scene = thesis_scene("change_mass_floor2")
    old_est, old_ctl, _ = check_design(scene, design_model(scene))
    changed = thesis_scene("change_mass_floor2", ["design.after_events=1"])
    new_est, new_ctl, _ = check_design(changed, design_model(changed))
    old_est.x = np.arange(8.0) * 1e-3
    old_est.t, old_est.force = 12.5, 0.03
    old_ctl.set_limit(0.02)
    handover = Handover(400, 12.5, None, design_model(changed), new_est, new_ctl)
    estimator = handover.apply(old_est, old_ctl)
    assert estimator is new_est
    np.testing.assert_array_equal(estimator.x, old_est.x)      # same coordinates: lumped, 8
    assert (estimator.t, estimator.force) == (12.5, 0.03)
    assert old_ctl.law is new_ctl.law and old_ctl.limit == 0.02


BAD = [
    (["adaptation.enabled=true", "controller.type=euk_floor", "estimator.type=truth"],
     "adaptation.enabled: hands over an LQG design"),
    (["adaptation.enabled=true", "adaptation.identification_window=200"],
     "adaptation.identification_window: 200 s is longer than the run after controller.start"),
    (["adaptation.enabled=true", "adaptation.detection_window=141"],
     "adaptation.detection_window: 141 s is longer"),
]


@pytest.mark.parametrize(("sets", "message"), BAD, ids=[m[:30] for _, m in BAD])
def test_bad_adaptation_settings_are_refused_where_launch_checks(sets, message) -> None:
    scene = thesis_scene("change_mass_floor2", sets)
    with pytest.raises(InputError, match=message):
        check_loop(scene)
    with pytest.raises(InputError, match=message):
        check_adaptation(scene)


def test_real_time_is_refused_where_launch_checks() -> None:
    scene = thesis_scene("change_mass_floor2", ["adaptation.enabled=true"])
    with pytest.raises(InputError, match=r"adaptation\.enabled: lock-step only"):
        check_loop(scene, mode="realtime")


def test_closed_loop_refuses_a_window_longer_than_the_run_in_one_line() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "stillframe", "closed-loop", "scenes/change_mass_floor2.yaml",
         "--set", "adaptation.enabled=true", "--set", "adaptation.identification_window=500"],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "identification_window: 500 s" in done.stderr


@pytest.mark.slow
@pytest.mark.parametrize("name", CHANGE_SCENES)
def test_the_one_process_adaptation_detects_identifies_and_hands_over(name: str) -> None:
    """The shipped scene with the adaptation on: one detection, within 15 s of the change; the
    frequencies identified and those of the design model within 1 % of the true changed
    model's (the roots of det(K − ω² M), independently assembled); one hand-over, before the
    evaluation window, its design's poles inside the unit circle."""
    scene = thesis_scene(name, ["adaptation.enabled=true"])
    history = run_closed_loop(scene)
    events = history.evaluation["adaptation"]["events"]
    assert [e["kind"] for e in events] == ["detection", "design"]
    detection, design = events
    change = scene.events[0].time
    assert change < detection["t"] <= change + 15.0
    assert detection["onset_s"] >= change
    truth = characteristic_frequencies(changed_scene(scene, 1))
    np.testing.assert_allclose(design["identified_hz"], truth, rtol=0.01)
    np.testing.assert_allclose(design["design_hz"], truth, rtol=0.01)
    assert design["largest_pole"] < 1.0
    assert design["handover_s"] < scene.duration - scene.evaluation.window


#: the false-alarm run: 20 minutes of the loop without an event (300 updates after the reference)
FALSE_ALARM_S = 1210.0


@pytest.mark.long
def test_no_false_alarm_in_twenty_minutes_without_a_change() -> None:
    """The mass scene without its event for 1210 s (control from 10 s): 298 detection updates
    after the reference, none declares a change, and the largest CUSUM statistic stays below
    the threshold. With zero alarms in U updates, the probability of a false alarm per update
    is below 3 / U at 95 % confidence (the rule of three; updates half overlap, so U / 2
    independent ones give 6 / U): 2 % per update, one false alarm per 200 s of watching at
    worst. What it measures is the margin (printed): the statistic's maximum against h."""
    scene = thesis_scene("change_mass_floor2", ["adaptation.enabled=true", "events=[]",
                                                f"duration={FALSE_ALARM_S}"])
    report = run_closed_loop(scene).evaluation["adaptation"]
    watched = [u for u in report["updates"] if u["statistic"] is not None]
    largest = max(u["statistic"] for u in watched)
    print(f"{len(watched)} updates watched, largest statistic {largest:.3g} "
          f"(threshold {scene.adaptation.threshold:g})")
    assert report["events"] == []
    assert len(watched) >= 290
    assert largest < scene.adaptation.threshold
