"""The command line loads only what it needs: a named command imports its own module, the list
of commands imports none; each module registers the command its name says."""

from __future__ import annotations

import argparse
import ast
import subprocess
import sys

from stillframe.app.cli import COMMANDS, build_parser, command_name, synopsis

HEAVY = ("numpy", "scipy", "rclpy", "cyclonedds", "rosbags", "stillframe.app.launcher")


def test_each_module_registers_the_command_of_its_name() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert list(sub.choices) == [command_name(m) for m in COMMANDS]
    for module in COMMANDS:
        assert synopsis(module) and "``" not in synopsis(module), module


def imported_after(*argv: str) -> list[str]:
    code = ("import sys; from stillframe.app.cli import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True,
                          timeout=120)
    return ast.literal_eval(done.stdout.splitlines()[-1])


def test_help_and_a_light_command_import_nothing_heavy() -> None:
    assert imported_after("--help") == []
    assert imported_after("daemon", "--help") == []
    assert imported_after("node", "--help") == []
    assert "stillframe.app.launcher" in imported_after("launch", "--help")   # its own module
