"""The suite's own helpers, where a fault would make tests fail by timing rather than by the
code they test."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.support.cli_fuzz import Hang, bounded
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


def busy(seconds: float) -> None:
    """Use ``seconds`` of this process's CPU."""
    began = time.process_time()
    while time.process_time() - began < seconds:
        pass


def test_the_fuzz_bound_counts_cpu_for_a_busy_case_and_wall_time_for_a_blocked_one(
        tmp_path: Path) -> None:
    """A busy case is ended by its CPU time; a blocked one (a FIFO opened without a writer)
    uses no CPU and is ended by the wall time; after a case that ended in time, neither timer
    fires."""
    with pytest.raises(Hang, match=r"0\.3 s of CPU"), bounded(cpu_s=0.3, wall_s=600):
        busy(600)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(Hang, match=r"within 0\.5 s$"), bounded(cpu_s=600, wall_s=0.5):
        fifo.open().close()     # blocks: no writer
    with bounded(cpu_s=0.2, wall_s=0.2):
        pass
    busy(0.3)
    time.sleep(0.3)
