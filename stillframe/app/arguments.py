"""Pieces shared by the subcommands: scene arguments, terminal tables and JSON output."""

from __future__ import annotations

import argparse
import json
import sys
import time
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
    try:
        found = find_scene(text)
    except OSError:     # a name the file system refuses (too long): loading it says so
        return Path(text)
    if found is None and (Path(text).suffix or "/" in text):
        return Path(text)
    if found is None:
        raise argparse.ArgumentTypeError(
            f"{text!r} is neither a scene file nor a shipped scene (shipped: "
            f"{', '.join(shipped_scenes())})")
    return found

#: the longest duration a command takes (the scene key ``duration``'s bound)
MAX_SECONDS = 1e6


def add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    """SCENE, repeatable ``--set dotted.key=value`` and ``--json``."""
    parser.add_argument("scene", metavar="SCENE", type=scene_path, help=SCENE_HELP)
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="override a scene value, e.g. --set model.type=fe (repeatable; YAML values)",
    )
    add_json_argument(parser)


def seconds(text: str) -> float:
    """An argparse ``type`` for a duration: a finite number of seconds in (0, 1e6] (the scene's
    ``duration`` bound); anything else is a usage error naming the value (exit 2)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not 0 < value <= MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"{text!r}: seconds must lie in (0, {MAX_SECONDS:g}]")
    return value


def whole(low: int, high: int) -> Any:
    """An argparse ``type`` for a count with physical bounds (runs, workers, mesh elements,
    ports): a whole number in [low, high], else a usage error naming it (exit 2)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text[:40]!r} is not a whole number") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{value}: must lie in [{low}, {high}]")
        return value

    parse.__name__ = "whole number"
    return parse


#: the niceness values a process may take without privilege (``nice(1)``)
NICE_RANGE = (0, 19)


def add_priority_arguments(parser: argparse.ArgumentParser, *, nice: int, who: str) -> None:
    """``--nice N`` (default ``nice``) and ``--idle``: how far ``who`` (a process beside the loop:
    the monitor, the recorder) steps back from the loop's nodes for CPU time; neither needs
    privilege (:func:`apply_priority`)."""
    parser.add_argument("--nice", type=whole(*NICE_RANGE), default=nice, metavar="N",
                        help=f"lower the {who}'s CPU priority by N, 0..19 (default {nice}), so "
                             "that under load the loop's nodes come first")
    parser.add_argument("--idle", action="store_true",
                        help=f"run the {who} at SCHED_IDLE: only on CPU time the loop leaves "
                             f"unused (on a busy machine the {who} then falls behind, never the "
                             "loop)")


def apply_priority(args: argparse.Namespace) -> None:
    """Apply ``--nice`` and ``--idle`` to this process; call it before the middleware starts
    its threads, which inherit both."""
    from stillframe.node_runtime.realtime import run_idle, run_nicer

    run_nicer(args.nice)
    if args.idle:
        run_idle()


def add_json_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--json`` to ``parser``: the command then prints one JSON document (:func:`emit_json`)
    instead of its tables."""
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
    """Print ``document`` to stdout as indented JSON, with a final newline."""
    json.dump(document, sys.stdout, indent=2)
    sys.stdout.write("\n")


def add_executor_arguments(parser: argparse.ArgumentParser) -> None:
    """``--workers K`` and ``--scheduler tcp://HOST:PORT`` (stillframe.studies.executor)."""
    parser.add_argument("--workers", type=whole(1, 1024), default=None, metavar="K",
                        help="local worker processes (default: one per core)")
    parser.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                        help="run on this Dask scheduler's workers instead of a local cluster")


class Progress:
    """Stage messages with elapsed time on stderr."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.start = time.perf_counter()

    def __call__(self, message: str) -> None:
        if self.enabled:
            print(f"[{time.perf_counter() - self.start:7.2f} s] {message}", file=sys.stderr,
                  flush=True)
