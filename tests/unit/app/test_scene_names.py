"""SCENE on the command line: a file path, or a shipped scene by its name (one helper for every
command taking a SCENE)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import pytest

from stillframe.app.arguments import scene_path
from stillframe.app.cli import build_parser
from stillframe.locations import SCENES_DIR, find_scene, shipped_scenes


def test_a_shipped_scene_is_found_by_name_and_a_path_still_works(tmp_path: Path) -> None:
    assert find_scene("thesis_lqg") == SCENES_DIR / "thesis_lqg.yaml"
    assert find_scene("thesis_lqg.yaml") == SCENES_DIR / "thesis_lqg.yaml"
    own = tmp_path / "thesis_lqg.yaml"
    own.write_text("name: mine\n")
    assert find_scene(str(own)) == own
    # a file of that name in the working directory wins over the shipped one, as a path does
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        assert find_scene("thesis_lqg.yaml") == Path("thesis_lqg.yaml")
    finally:
        os.chdir(cwd)
    assert set(shipped_scenes()) == {p.stem for p in SCENES_DIR.glob("*.yaml")}
    assert "thesis_lqg" in shipped_scenes()


@pytest.mark.parametrize("argv", [
    ["launch", "thesis_lqg"], ["modes", "thesis_lqg"], ["simulate", "thesis_lqg"],
    ["closed-loop", "thesis_lqg"], ["montecarlo", "thesis_lqg", "--vary", "duration=1"],
    ["experiment", "thesis_lqg"], ["reproduce", "thesis_lqg"],
])
def test_every_scene_command_resolves_a_name(argv: list[str]) -> None:
    args = build_parser().parse_args(argv)
    scene = args.scenes[0] if argv[0] == "reproduce" else args.scene
    assert Path(scene) == SCENES_DIR / "thesis_lqg.yaml"


def test_an_unknown_name_lists_the_shipped_scenes() -> None:
    with pytest.raises(argparse.ArgumentTypeError) as info:
        scene_path("thesis_lgq")
    assert "thesis_lqg" in str(info.value) and "\n" not in str(info.value)
    # a path that does not exist is kept: loading it says so in one line (test_scene.py)
    assert scene_path("missing.yaml") == Path("missing.yaml")
