"""Pieces shared by the subcommands: scene arguments, terminal tables and JSON output."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from stillframe.config.scene import Scene, load_scene
from stillframe.fidelity.auto_model import Choice, resolve_model


def add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    """SCENE, repeatable ``--set dotted.key=value`` and ``--json``."""
    parser.add_argument("scene", metavar="SCENE", help="scene file (YAML)")
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
    return resolve_model(load_scene(args.scene, args.overrides))


def emit_json(document: Any) -> None:
    json.dump(document, sys.stdout, indent=2)
    sys.stdout.write("\n")
