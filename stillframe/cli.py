"""The ``stillframe`` command: one subcommand per module listed in :data:`COMMANDS`.

Each listed module exposes ``register(subparsers)``, which adds its parser and sets
``func=run`` on it; ``run(args)`` returns the process exit code. Modules are imported only
when listed here, so the core never imports the tools built on top of it at import time.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from stillframe.errors import InputError

COMMANDS: tuple[str, ...] = (
    "stillframe.commands.modes",
    "stillframe.commands.simulate",
    "stillframe.commands.bench",
    "stillframe.commands.topic",
    "stillframe.commands.param",
    "stillframe.commands.bag",
    "stillframe.commands.record",
    "stillframe.commands.play",
    "stillframe.commands.monitor",
    "stillframe.commands.identify",
    "stillframe.commands.identify_daisy",
    "stillframe.commands.closed_loop",
    "stillframe.commands.launch",
    "stillframe.commands.reproduce",
    "stillframe.commands.demo",
    "stillframe.commands.ph",
    "stillframe.commands.montecarlo",
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
    except InputError as exc:
        print(f"stillframe {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
