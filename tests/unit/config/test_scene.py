"""Scene loading, overrides and validation: every class of error names its key, exit code 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from stillframe.config.scene import load_scene, scene_from_dict
from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT

ROOT = REPO_ROOT
SCENES = sorted((ROOT / "scenes").glob("*.yaml"))


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_shipped_scenes_load(path: Path) -> None:
    scene = load_scene(path)
    assert scene.name == path.stem


def test_defaults_are_the_thesis_rig() -> None:
    scene = scene_from_dict({"name": "x"})
    assert scene.rig.floor_masses == (1.281, 0.814, 1.380)
    assert scene.rig.columns.lengths == (0.23, 0.28, 0.23)
    assert scene.rig.pendulum.inertia == 8.32e-4
    assert scene.damping.beta == -2.8815e-4


def test_overrides_parse_numbers_lists_and_scientific_notation() -> None:
    scene = scene_from_dict(
        {"name": "x"},
        ["model.type=fe", "integrator.dt=1e-4", "rig.floor_masses=[1, 2, 3]",
         "excitation.frequencies_hz=[1.5]", "excitation.amplitudes=[0.2]"],
    )
    assert scene.model.type == "fe"
    assert scene.integrator.dt == 1e-4
    assert scene.rig.floor_masses == (1.0, 2.0, 3.0)
    assert scene.excitation.frequencies_hz == (1.5,)


ERRORS = [
    # (scene dict, overrides, text the one-line message must contain)
    ({"name": "x", "colour": 1}, [], "colour: unknown key"),
    ({"name": "x", "rig": {"pendulum": {"lenght": 1}}}, [], "rig.pendulum.lenght: unknown key"),
    ({}, [], "name: missing required field"),
    ({"name": "x", "duration": "long"}, [], "duration: expected a number"),
    ({"name": "x", "model": {"elements_per_column": 2.5}}, [], "expected a whole number"),
    ({"name": "x", "rig": {"gravity": True}}, [], "rig.gravity: expected a number"),
    ({"name": "x", "rig": {"floor_masses": [1, 2]}}, [], "rig.floor_masses: expected 3 values"),
    ({"name": "x", "rig": {"floor_masses": [1, -2, 3]}}, [],
     "rig.floor_masses: must lie in [1e-06, 1e+07]"),
    ({"name": "x", "rig": {"pendulum": {"mass": -0.1}}}, [], "rig.pendulum.mass: must lie in"),
    ({"name": "x", "rig": {"columns": {"lengths": [0.2, 0, 0.2]}}}, [], "must lie in [0.0001,"),
    ({"name": "x", "integrator": {"dt": 0}}, [], "integrator.dt: must lie in [1e-09, 1]"),
    ({"name": "x", "integrator": {"dt": -1e-3}}, [], "integrator.dt: must lie in [1e-09, 1]"),
    ({"name": "x", "integrator": {"method": "euler"}}, [], "integrator.method: 'euler' is not"),
    ({"name": "x", "model": {"type": "fe"}, "damping": {"model": "modal"}},
     ["model.type=modal", "model.modes=50"], "model.modes: 50 retained modes"),
    ({"name": "x", "model": {"type": "fe"}}, [], "damping.beta: Rayleigh damping"),
    ({"name": "x", "excitation": {"type": "harmonics", "amplitudes": [1, 2]}}, [],
     "need the same length"),
    ({"name": "x", "integrator": {"dt": 0.5}, "duration": 0.1}, [], "longer than duration"),
    ({"name": "x", "rig": 3}, [], "rig: expected a mapping"),
    ({"name": "x"}, ["model.type"], "--set model.type: expected dotted.key=value"),
    ({"name": "x", "duration": 3}, ["duration.x=1"], "duration is a value, not a section"),
    ({"name": "x"}, ["rig.gravity=[1, 2"], "value is not valid YAML"),
    ({"name": "x"}, ["rig.gravity=.nan"], "rig.gravity: must be finite"),
]


@pytest.mark.parametrize(("data", "overrides", "message"), ERRORS)
def test_each_error_names_its_key(data: dict, overrides: list[str], message: str) -> None:
    from stillframe.dynamics.models import build_model

    with pytest.raises(InputError) as info:
        build_model(scene_from_dict(data, overrides))
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stillframe", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(
    ("setup", "args", "message"),
    [
        (None, ["modes", "missing.yaml"], "missing.yaml: cannot read the scene file"),
        ("name: [x", ["modes", "{p}"], "not valid YAML: "),
        ("- a\n- b\n", ["modes", "{p}"], "a scene is a mapping"),
        ("name: x\nrig: {floor_masses: [1, -1, 1]}\n", ["modes", "{p}"], "rig.floor_masses"),
        ("name: x\n", ["simulate", "{p}", "--set", "integrator.dt=-1"], "integrator.dt: must lie"),
        ("name: x\n", ["simulate", "{p}", "--out", "x.txt", "--duration", "0.01"], "use a .npz"),
        ("name: x\n", ["simulate", "{p}", "--duration", "-2"], "--duration: '-2': seconds"),
    ],
)
@pytest.mark.processes
def test_cli_errors_are_one_line_with_exit_code_2(tmp_path: Path, setup: str | None,
                                                  args: list[str], message: str) -> None:
    path = tmp_path / "scene.yaml"
    if setup is not None:
        path.write_text(setup)
    result = _run(*[a.format(p=path) for a in args])
    assert result.returncode == 2, result.stderr
    assert message in result.stderr
    assert "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
