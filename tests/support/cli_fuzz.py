"""The in-process harness of the fuzz suite (``tests/integration/test_fuzz_*.py``): run a
``stillframe`` command line in this process within a bound, check its one-line error, and walk
the real parser for every command."""

from __future__ import annotations

import argparse
import contextlib
import io
import signal
from collections.abc import Iterator

from stillframe.app import cli
from tests.support.waits import HANG_S

#: CPU seconds any one case may use: a runaway loop or an endless read (/dev/zero) fails the
#: test instead of the suite. CPU time, so that a loaded machine, which gives the case its CPU
#: late, does not run it out
BOUND_S = 30.0
#: hostile YAML values for --set (and scene text): non-finite, huge, tiny, wrong types, broken
#: syntax, deep nesting, non-ASCII and non-UTF-8 text
HOSTILE = [".nan", "nan", ".inf", "-.inf", "inf", "1e308", "-1e308", "1e-308", "-1", "0",
           "1" + "0" * 30, str(2**64), "1" + "0" * 5000, "'text'", "[1, 2", "{", "[]", "null",
           "true", "[" * 3000 + "]" * 3000, "{a: " * 500 + "1" + "}" * 500, "é", "\udcff\udcfe",
           "0x10", "- a\n- b"]


class Hang(BaseException):
    """A case that ran past :data:`BOUND_S` of CPU or :data:`HANG_S` of wall time (a
    BaseException: nothing under test catches it)."""


#: the interval timers of :func:`bounded` and the signal each sends
TIMERS = {signal.ITIMER_PROF: signal.SIGPROF, signal.ITIMER_REAL: signal.SIGALRM}


@contextlib.contextmanager
def bounded(cpu_s: float = BOUND_S, wall_s: float = HANG_S) -> Iterator[None]:
    """Raise Hang in the block once this process has used ``cpu_s`` of CPU in it, or once
    ``wall_s`` have passed."""
    def expire(signum: int, _frame: object) -> None:
        raise Hang(f"no answer within {cpu_s} s of CPU" if signum == signal.SIGPROF
                   else f"no answer within {wall_s} s")

    previous = {sig: signal.signal(sig, expire) for sig in TIMERS.values()}
    signal.setitimer(signal.ITIMER_PROF, cpu_s)
    signal.setitimer(signal.ITIMER_REAL, wall_s)
    try:
        yield
    finally:
        for timer, sig in TIMERS.items():
            signal.setitimer(timer, 0)
            signal.signal(sig, previous[sig])


def run(*argv: str) -> tuple[int, str, str]:
    """``stillframe ARGV`` in process: exit code, stdout, stderr."""
    out, err = io.StringIO(), io.StringIO()
    with bounded(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli.main(list(argv))
        except SystemExit as exc:     # argparse
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue(), err.getvalue()


def assert_one_line_error(argv: list[str], code: int, err: str, codes: set[int],
                          names: str = "") -> None:
    """Exit code of the error's kind, a last stderr line ``stillframe CMD: error: ...`` naming
    ``names`` (when given), no traceback."""
    shown = " ".join(a[:60] for a in argv)
    assert "Traceback" not in err, f"{shown}: {err[-2000:]}"
    assert code in codes, f"{shown}: exit {code}, expected {sorted(codes)}: {err[-600:]}"
    last = err.strip().splitlines()[-1] if err.strip() else ""
    assert last.startswith("stillframe") and ": error: " in last, f"{shown}: {err[-600:]}"
    assert names in last, f"{shown}: {last!r} does not name {names!r}"


def leaf_commands() -> list[tuple[list[str], argparse.ArgumentParser]]:
    """Every command (with its verb) of the real parser, and its parser."""
    found = []

    def walk(parser: argparse.ArgumentParser, path: list[str]) -> None:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            found.append((path, parser))
            return
        for name, sub in subs[0].choices.items():
            walk(sub, [*path, name])

    walk(cli.build_parser(), [])
    return found


def positionals(parser: argparse.ArgumentParser) -> list[str]:
    return [a.dest for a in parser._actions if not a.option_strings]


