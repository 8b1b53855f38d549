"""The ``stillframe`` command: one subcommand per module listed in :data:`COMMANDS`.

Each listed module exposes ``register(subparsers)``, which adds its parser and sets
``func=run`` on it; ``run(args)`` returns the process exit code. Modules are imported only
when listed here, so the core never imports the tools built on top of it at import time; and
a command line naming a command imports only that command's module (``stillframe topic list``
does not load the simulator). The list of commands (``stillframe --help``) reads each module's
summary from its docstring without importing it.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib
import importlib.util
import math
import os
import re
import signal
import sys
from pathlib import Path
from typing import Any, NoReturn

from stillframe import interrupts
from stillframe.config.environment import check_environment
from stillframe.errors import InputError, StillframeError

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
    "stillframe.app.commands.adapt",
    "stillframe.app.commands.ph",
    "stillframe.app.commands.montecarlo",
    "stillframe.app.commands.netns",
    "stillframe.app.commands.node",
    "stillframe.app.commands.interface",
    "stillframe.app.commands.daemon",
)


def _finite(text: str) -> float:
    """``float`` for argparse without nan and ±inf (no option means them)."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(text)
    return value


_finite.__name__ = "float"      # argparse's message: "invalid float value: 'nan'"


class _Parser(argparse.ArgumentParser):
    """A usage error is one line naming the argument, and where to read more (exit 2), as
    every other bad input; ``-h`` still prints the usage."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.register("type", float, _finite)     # every type=float option: no nan, no inf

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} -h)\n")


def _module_of(argv: list[str]) -> str | None:
    """The module of the command ``argv`` names (its first word that is not an option), if any
    listed module has that name (``closed-loop`` is ``closed_loop``)."""
    word = next((a for a in argv if not a.startswith("-")), "")
    wanted = f"stillframe.app.commands.{word.replace('-', '_')}"
    return wanted if wanted in COMMANDS else None


def command_name(module: str) -> str:
    """``closed-loop`` of ``stillframe.app.commands.closed_loop``."""
    return module.rsplit(".", 1)[1].replace("_", "-")


def synopsis(module: str) -> str:
    """What a command does, for the list of commands: the first clause of its module's
    docstring after the usage (``stillframe modes SCENE``: ...), markup removed, read without
    importing the module."""
    source = Path(importlib.util.find_spec(module).origin).read_text()
    text = " ".join((ast.get_docstring(ast.parse(source)) or "").split("\n\n")[0].split())
    text = re.sub(r":\w+:`([^`]+)`", r"\1", text.split("``: ", 1)[-1]).replace("``", "")
    return re.split(r"\. | \(|: ", text, maxsplit=1)[0].rstrip(".")


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser of every command (``argv`` None), or of the one ``argv`` names; when it names
    none (``--help``, a typo), the list of commands with their synopses, importing none."""
    parser = _Parser(
        prog="stillframe",
        description="Simulate, identify and control a flexible frame with an active mass damper.",
    )
    parser.add_argument("--verbose", action="store_true",
                        help="log the tools' own nodes (their middleware backend) too")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    only = _module_of(argv) if argv is not None else None
    if argv is not None and only is None:
        for name in COMMANDS:
            sub.add_parser(command_name(name), help=synopsis(name))
        return parser
    for name in (only,) if only else COMMANDS:
        importlib.import_module(name).register(sub)
    return parser


#: the exit code of a command whose reader went away (``| head``): a shell's for SIGPIPE
BROKEN_PIPE = 128 + signal.SIGPIPE


def _quiet_stdout() -> None:
    """After a broken pipe: nothing more goes to stdout, and the interpreter's last flush does
    not complain (Python's documented recipe, docs.python.org/3/library/signal.html)."""
    with contextlib.suppress(OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())


def main(argv: list[str] | None = None) -> int:
    """Run the command of ``argv`` and return its exit code. Without ``argv`` (the ``stillframe``
    executable, ``python -m stillframe``) this is the process's entry point: Ctrl-C is answered
    from here on, and the process ends here (:mod:`stillframe.interrupts`)."""
    process = argv is None
    argv = sys.argv[1:] if argv is None else argv
    module = _module_of(argv)
    prog = f"stillframe {command_name(module)}" if module else "stillframe"
    if process:
        interrupts.starting(prog)
    args = build_parser(argv).parse_args(argv)
    if process:
        interrupts.working()
    code = interrupts.run_work(prog, lambda: _run(args))
    if process:
        interrupts.finish(prog, code)
    return code


def _run(args: argparse.Namespace) -> int:
    """The command's ``run``, after the environment's checks: its exit code; a StillframeError,
    a broken pipe or an OSError on a named file as one line and its code (unless it came after
    an interruption, which :func:`stillframe.interrupts.run_work` answers)."""
    if args.verbose:
        from stillframe.app.ros_tools import VERBOSE_ENV

        os.environ[VERBOSE_ENV] = "1"  # read by the tools' own nodes
    try:
        check_environment()
        code = int(args.func(args) or 0)
        sys.stdout.flush()
        return code
    except StillframeError as exc:
        if interrupts.received():
            raise
        print(f"stillframe {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:
        _quiet_stdout()
        return BROKEN_PIPE
    except OSError as exc:
        # a file named on the command line (or under a directory named there) that cannot be
        # written or read: read-only, a full disk (no file name then), a parent that is a file
        if interrupts.received():
            raise
        where = f"{exc.filename}: " if exc.filename is not None else ""
        print(f"stillframe {args.command}: error: {where}{exc.strerror or exc}",
              file=sys.stderr)
        return InputError.exit_code


if __name__ == "__main__":
    sys.exit(main())
