"""The suite's own helpers, where a fault would make tests fail by timing rather than by the
code they test."""

from __future__ import annotations

import subprocess
import sys

from tests.support.middleware import wait_for_line

THREE_LINES_AT_ONCE = ("import sys, time; sys.stdout.write('first\\nready\\nafter\\n'); "
                       "sys.stdout.flush(); time.sleep(30)")


def test_wait_for_line_finds_a_line_written_in_the_same_instant_as_the_one_before() -> None:
    """Three lines in one write reach the reader in one read; the helper still finds the second,
    and leaves the third in the pipe for the next reader."""
    proc = subprocess.Popen([sys.executable, "-c", THREE_LINES_AT_ONCE], stdout=subprocess.PIPE,
                            text=True)
    try:
        assert wait_for_line(proc, "ready", timeout=20) == "ready\n"
        assert proc.stdout.readline() == "after\n"
    finally:
        proc.kill()
        proc.communicate()
