"""The typed scene: frozen dataclasses that a type checker follows, and that go back to the
plain dicts, YAML and ``--set`` overrides they were loaded from."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from stillframe.config.scene import Scene, load_scene, scene_from_dict
from stillframe.locations import REPO_ROOT

ROOT = REPO_ROOT
SCENES = sorted((ROOT / "scenes").glob("*.yaml"))

#: the configuration and consumers of every layer that mypy checks without an error
TYPED = ["stillframe/config", "stillframe/dynamics/models", "stillframe/dynamics/excitation.py",
         "stillframe/plant", "stillframe/loop/closed_loop.py", "stillframe/contract/signals.py"]

MISTAKES = '''\
from stillframe.config.scene import load_scene

scene = load_scene("scene.yaml")
masses = scene.rig.floor_mases
if scene.estimator.type == "kff":
    pass
scene.rig.gravity = 1.0
'''


def _dotted(data: dict[str, Any], prefix: str = "") -> list[str]:
    """``--set`` overrides that give every leaf of ``data`` its value (JSON is YAML)."""
    out = []
    for name, value in data.items():
        if isinstance(value, dict):
            out += _dotted(value, f"{prefix}{name}.")
        else:
            out.append(f"{prefix}{name}={json.dumps(value)}")
    return out


def test_a_misspelled_key_is_an_attribute_error() -> None:
    scene = scene_from_dict({"name": "x"})
    with pytest.raises(AttributeError, match="floor_mases"):
        _ = scene.rig.floor_mases  # type: ignore[attr-defined]


def test_sections_are_frozen() -> None:
    scene = scene_from_dict({"name": "x"})
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.rig.pendulum.mass = 1.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.duration = 1.0  # type: ignore[misc]
    assert scene.rig.pendulum.mass == 0.083 and scene.duration == 10.0


def test_declared_defaults_are_what_loading_fills_in() -> None:
    """The dataclass defaults pass their own checks and have the loaded types (float, not int)."""
    bare = Scene(name="x")
    loaded = scene_from_dict({"name": "x"})
    assert bare == loaded
    assert scene_from_dict(bare.to_dict()) == bare


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_to_dict_round_trips_through_yaml_json_and_set(path: Path) -> None:
    scene = load_scene(path)
    data = scene.to_dict()
    assert scene_from_dict(data) == scene
    assert scene_from_dict(yaml.safe_load(yaml.safe_dump(data))) == scene
    assert scene_from_dict(json.loads(json.dumps(data))) == scene
    assert scene_from_dict({}, _dotted(data)) == scene
    assert isinstance(data["rig"]["floor_masses"], list)


def test_lists_load_as_tuples_of_floats() -> None:
    scene = scene_from_dict({"name": "x", "rig": {"floor_masses": [1, 2, 3]}})
    assert scene.rig.floor_masses == (1.0, 2.0, 3.0)
    assert all(type(m) is float for m in scene.rig.floor_masses)


def test_mypy_follows_the_scene_into_its_consumers(tmp_path: Path) -> None:
    """mypy checks the configuration and some consumers cleanly, and flags a misspelled key, a
    misspelled choice and an assignment to a frozen section."""
    mistakes = tmp_path / "mistakes.py"
    mistakes.write_text(MISTAKES)
    # a cache of its own: mypy's shared one answers for a module ``mistakes`` of the same text
    # with the errors, and the path, of an earlier run's file
    done = subprocess.run([sys.executable, "-m", "mypy", "--no-error-summary", "--cache-dir",
                           str(tmp_path / "mypy_cache"), *TYPED, str(mistakes)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    errors = [line for line in done.stdout.splitlines() if ": error:" in line]
    assert all(line.startswith(str(mistakes)) for line in errors), done.stdout
    assert len(errors) == 3, done.stdout
    assert '"Rig" has no attribute "floor_mases"' in errors[0]
    assert "Non-overlapping equality check" in errors[1] and "'kff'" in errors[1]
    assert 'Property "gravity" defined in "Rig" is read-only' in errors[2]
