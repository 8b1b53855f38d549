"""The adaptation through the nodes (docs/adaptation.md): a lock-step launch of a shortened
change scene gives the one-process loop's numbers to the last bit, with the same detection and
the same design handed over at the same sample in both nodes; controller_node's ``design``
parameter refuses a design that fails its check (one line with the reason, the running one
kept), takes a model file, and rolls back to the scene's design."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from stillframe.app.launcher import run_scene
from stillframe.config.scene import load_scene
from stillframe.contract.adaptation_events import event_message, read_event_message
from stillframe.design.identified import load_identified_structure, storeys, write_mkr_file
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.loop.wiring import design_model
from tests.support.middleware import run_stillframe
from tests.support.nodes import SCENES, params_file, start_node, stop, wait_for_log

#: the mass scene shortened: control from 2 s, the reference set by 40 s, the mass at 42 s, a
#: 10 s identification window, the hand-over near 54 s, the last 10 s evaluated
SHORT = ["duration=70", "controller.start=2", "evaluation.window=10",
         "events=[{time: 42, floor: 2, mass_factor: 1.3}]",
         "adaptation.identification_window=10", "adaptation.enabled=true"]
EVALUATION_KEYS = ("reduction_pct", "peak_uncontrolled", "peak_controlled", "peak_command")


@pytest.mark.slow
def test_the_adaptive_lockstep_launch_equals_the_one_process_loop(ros_domain: int,
                                                                 tmp_path: Path) -> None:
    scene = SCENES / "change_mass_floor2.yaml"
    launched = run_scene(scene, SHORT, out=tmp_path)
    reference = run_closed_loop(load_scene(scene, SHORT))
    for key in EVALUATION_KEYS:
        assert launched.evaluation[key] == reference.evaluation[key], key
    with np.load(launched.history_file) as hist:
        np.testing.assert_array_equal(hist["truth"], reference.truth)
        np.testing.assert_array_equal(hist["command"], reference.command)
    events = launched.evaluation["adaptation"]["events"]
    assert [e["kind"] for e in events] == ["detection", "design"]
    design = events[1]
    path = Path(design.pop("file"))
    assert events == reference.evaluation["adaptation"]["events"]
    assert 42.0 < events[0]["t"] <= 57.0
    # the file the nodes took holds the storeys of the record, to the last bit
    written = load_identified_structure(path)
    np.testing.assert_array_equal(written.mass, design["mass"])
    np.testing.assert_array_equal(written.stiffness, design["stiffness"])
    record = json.loads((tmp_path / "adaptation.json").read_text())
    assert record["updates"] == reference.evaluation["adaptation"]["updates"]


def test_an_adaptation_event_crosses_its_topic_as_it_was() -> None:
    record = {"kind": "detection", "t": 47.96875, "onset_s": 43.96875, "mode": 3,
              "statistic": 50.5, "reference_hz": [1.1, 1.98, 5.79, 8.82],
              "reference_std_hz": [0.01, 0.01, 0.01, 0.01],
              "frequency_hz": [1.1, 1.91, 5.76, 8.07]}
    msg = event_message(47_968_750_000, "estimator_node", record)
    assert read_event_message(msg) == [record]
    assert msg.status[0].level == 1 and "8.82 -> 8.07 Hz" in msg.status[0].message


@pytest.mark.slow
def test_the_design_parameter_refuses_a_bad_design_takes_a_file_and_rolls_back(
        ros_domain: int, tmp_path: Path) -> None:
    """controller_node alone (real time, waiting for a simulator that never comes): a model
    file whose floor 1 stands apart on a negative stiffness is refused with the model file's
    reason (its stiffness is not positive semidefinite, so no design is tried; the design check
    itself is held by tests/unit/loop/test_adaptation.py) and the parameter keeps its value; the
    true changed structure's file is taken; ``scene@5`` (a rollback) is taken."""
    pfile = params_file(tmp_path, "change_mass_floor2", [], mode="realtime")
    node = start_node("controller_node", pfile)
    try:
        wait_for_log(node, "lifecycle: activate done", timeout=60)
        target = "/frame/controller_node"
        stiffness = np.diag([-100.0, 2000.0, 1000.0])
        stiffness[1, 2] = stiffness[2, 1] = -900.0
        bad = tmp_path / "bad.yaml"
        write_mkr_file(bad, storeys(np.diag([1.3, 1.0, 1.4]), stiffness, np.eye(3) * 0.5, "x"),
                       "a bad identification")
        done = run_stillframe("param", "set", target, "design", f"{bad}@3.0")
        assert done.returncode != 0
        assert "not positive semidefinite" in done.stderr + done.stdout
        assert done.stderr.count("\n") <= 1
        got = run_stillframe("param", "get", target, "design", "--json")
        assert json.loads(got.stdout)["value"] == "scene"
        true_after = load_scene(SCENES / "change_mass_floor2.yaml", ["design.after_events=1"])
        good = tmp_path / "good.yaml"
        write_mkr_file(good, design_model(true_after).structure, "the true structure after")
        assert run_stillframe("param", "set", target, "design", f"{good}@3.0").returncode == 0
        assert run_stillframe("param", "set", target, "design", "scene@5").returncode == 0
        got = run_stillframe("param", "get", target, "design", "--json")
        assert json.loads(got.stdout)["value"] == "scene@5"
    finally:
        code, err = stop(node)
    assert code == 0, err[-2000:]
