"""``stillframe adapt``: bad input is one line and exit code 2 before any process starts; a
shortened change scene runs the three loops through the nodes and its JSON holds exactly the
issue's ``adaptation`` keys, each run's reductions as its sim_node wrote them, the change where
the scene put it, the detection after it and the true frequencies of the changed rig (the roots
of det(K − ω² M), assembled independently)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from stillframe.config.scene import changed_scene, load_scene
from tests.integration.test_adaptation_nodes import SHORT
from tests.support.middleware import run_stillframe
from tests.support.nodes import SCENES
from tests.support.scenes import characteristic_frequencies

BAD = [
    (["scenes/thesis_lqg.yaml"], "events: the scene changes nothing"),
    (["scenes/change_mass_floor2.yaml", "--set", "adaptation.identification_window=500"],
     "adaptation.identification_window: 500 s is longer than the run"),
    (["scenes/change_mass_floor2.yaml", "--set", "design.model=file"],
     "design.model: file; the oracle designs on the true model"),
    (["scenes/change_mass_floor2.yaml", "--set", "controller.type=passivity"],
     "adaptation.enabled: hands over an LQG design"),
]


@pytest.mark.parametrize(("args", "message"), BAD, ids=[m[:24] for _, m in BAD])
def test_bad_input_is_one_line_and_exit_2_before_anything_runs(args: list[str], message: str,
                                                                tmp_path: Path) -> None:
    done = run_stillframe("adapt", *args, "--out", str(tmp_path / "out"))
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and message in done.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.long      # three 70 s scenes (fixed, adaptive, oracle); test_adaptation_nodes and
#                        tests/unit/loop/test_adaptation.py hold the hand-over by default
def test_the_three_runs_and_the_issues_json(ros_domain: int, tmp_path: Path) -> None:
    args = [a for s in SHORT for a in ("--set", s)]
    done = run_stillframe("adapt", "scenes/change_mass_floor2.yaml", *args, "--out",
                          str(tmp_path), "--json", timeout=1800)
    assert done.returncode == 0, done.stderr[-3000:]
    doc = json.loads(done.stdout)
    a = doc["adaptation"]
    assert set(a) == {"change_at_s", "detected_at_s", "identified_hz", "true_hz",
                      "reduction_pct"}
    assert set(a["reduction_pct"]) == {"fixed", "adaptive", "oracle"}
    for name, reductions in a["reduction_pct"].items():
        assert set(reductions) == {"displacement", "velocity"}
        assert all(len(v) == 3 for v in reductions.values())
        written = json.loads((tmp_path / name / "result.json").read_text())
        assert written["reduction_pct"] == reductions
    assert a["change_at_s"] == 42.0
    assert 42.0 < a["detected_at_s"] <= 57.0
    scene = load_scene(SCENES / "change_mass_floor2.yaml", SHORT)
    # |λ| of the damped modes against the undamped roots: within 1e-3 (damping ratios < 5 %)
    np.testing.assert_allclose(a["true_hz"], characteristic_frequencies(changed_scene(scene, 1)),
                               rtol=1e-3)
    assert len(a["identified_hz"]) == 4
    assert (tmp_path / "timeline.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "adapt.json").read_text())["adaptation"] == a
