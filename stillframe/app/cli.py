"""The ``stillframe`` command: one subcommand per module listed in :data:`COMMANDS`.

Each listed module exposes ``register(subparsers)``, which adds its parser and sets
``func=run`` on it; ``run(args)`` returns the process exit code. Modules are imported only
when listed here, so the core never imports the tools built on top of it at import time; and
a command line naming a command imports only that command's module (``stillframe topic list``
does not load the simulator), the others when asked for help.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from stillframe.app.ros_tools import VERBOSE_ENV
from stillframe.errors import StillframeError

COMMANDS: tuple[str, ...] = (
    "stillframe.app.commands.modes",
    "stillframe.app.commands.simulate",
    "stillframe.app.commands.bench",
    "stillframe.app.commands.topic",
    "stillframe.app.commands.param",
    "stillframe.app.commands.bag",
    "stillframe.app.commands.record",
    "stillframe.app.commands.play",
    "stillframe.app.commands.monitor",
    "stillframe.app.commands.identify",
    "stillframe.app.commands.identify_daisy",
    "stillframe.app.commands.closed_loop",
    "stillframe.app.commands.launch",
    "stillframe.app.commands.reproduce",
    "stillframe.app.commands.demo",
    "stillframe.app.commands.experiment",
    "stillframe.app.commands.ph",
    "stillframe.app.commands.montecarlo",
    "stillframe.app.commands.netns",
    "stillframe.app.commands.node",
    "stillframe.app.commands.interface",
    "stillframe.app.commands.daemon",
)


def _module_of(argv: list[str]) -> str | None:
    """The module of the command ``argv`` names (its first word that is not an option), if any
    listed module has that name (``closed-loop`` is ``closed_loop``)."""
    word = next((a for a in argv if not a.startswith("-")), "")
    wanted = f"stillframe.app.commands.{word.replace('-', '_')}"
    return wanted if wanted in COMMANDS else None


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or only of the one ``argv`` names."""
    parser = argparse.ArgumentParser(
        prog="stillframe",
        description="Simulate, identify and control a flexible frame with an active mass damper.",
    )
    parser.add_argument("--verbose", action="store_true",
                        help="log the tools' own nodes (their middleware backend) too")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    only = _module_of(argv) if argv is not None else None
    for name in (only,) if only else COMMANDS:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser(argv).parse_args(argv)
    if args.verbose:
        os.environ[VERBOSE_ENV] = "1"  # read by the tools' own nodes
    try:
        return int(args.func(args) or 0)
    except StillframeError as exc:
        print(f"stillframe {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
