"""The ``stillframe`` command: one subcommand per module listed in :data:`COMMANDS`.

Each listed module exposes ``register(subparsers)``, which adds its parser and sets
``func=run`` on it; ``run(args)`` returns the process exit code. Modules are imported only
when listed here, so the core never imports the tools built on top of it at import time.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from stillframe.errors import StillframeError

COMMANDS: tuple[str, ...] = (
    "stillframe.app.commands.modes",
    "stillframe.app.commands.simulate",
    "stillframe.app.commands.bench",
    "stillframe.app.commands.topic",
    "stillframe.app.commands.param",
    "stillframe.app.commands.lifecycle",
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
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="stillframe",
        description="Simulate, identify and control a flexible frame with an active mass damper.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except StillframeError as exc:
        print(f"stillframe {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
