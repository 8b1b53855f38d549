"""Pieces shared by the subcommands: scene arguments, terminal tables and JSON output."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from stillframe.locations import find_scene, shipped_scenes

if TYPE_CHECKING:
    from stillframe.config.scene import Scene
    from stillframe.fidelity.auto_model import Choice

SCENE_HELP = "scene file (YAML), or the name of a shipped scene (e.g. thesis_lqg)"


def scene_path(text: str) -> Path:
    """SCENE as a path (an argparse ``type``): a file, or a shipped scene by name. A path that
    does not exist is kept (loading it names it in one line); a bare name matching no shipped
    scene is an argparse error listing them."""
    found = find_scene(text)
    if found is None and (Path(text).suffix or "/" in text):
        return Path(text)
    if found is None:
        raise argparse.ArgumentTypeError(
            f"{text!r} is neither a scene file nor a shipped scene (shipped: "
            f"{', '.join(shipped_scenes())})")
    return found


def add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    """SCENE, repeatable ``--set dotted.key=value`` and ``--json``."""
    parser.add_argument("scene", metavar="SCENE", type=scene_path, help=SCENE_HELP)
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="override a scene value, e.g. --set model.type=fe (repeatable; YAML values)",
    )
    add_json_argument(parser)


def add_json_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON document")


def scene_from_args(args: argparse.Namespace) -> Scene:
    """The scene of SCENE and ``--set``, with ``model.type: auto`` resolved."""
    return scene_and_choice(args)[0]


def scene_and_choice(args: argparse.Namespace) -> tuple[Scene, Choice | None]:
    """The scene as :func:`scene_from_args` and the ``model.type: auto`` choice (None if none)."""
    from stillframe.config.scene import load_scene
    from stillframe.fidelity.auto_model import resolve_model

    return resolve_model(load_scene(args.scene, args.overrides))


def emit_json(document: Any) -> None:
    json.dump(document, sys.stdout, indent=2)
    sys.stdout.write("\n")
