"""``stillframe record --nice N --idle`` (issue 32): the recorder steps back from the loop's nodes
for CPU time, and every thread it starts (the middleware's receive threads, the bag's writer)
inherits that; the kernel's view of each thread (``/proc``) is the independent check."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from stillframe.locations import REPO_ROOT
from tests.support.middleware import child_env, finish, scheduling


@pytest.mark.parametrize(("args", "expected"), [
    (["--nice", "7"], {(os.SCHED_OTHER, 7)}),
    (["--nice", "3", "--idle"], {(os.SCHED_IDLE, 3)}),
])
def test_every_recorder_thread_runs_at_the_priority_asked(
        tmp_path: Path, ros_domain: int, args: list[str], expected: set[tuple[int, int]]) -> None:
    bag = tmp_path / "bag"
    proc = subprocess.Popen([sys.executable, "-m", "stillframe", "record", "-o", str(bag), "--all",
                             *args], env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        # the bag is opened after the node exists: its middleware threads have started by then
        while not list(bag.glob("*.mcap")):
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
            time.sleep(0.1)
        threads = len(os.listdir(f"/proc/{proc.pid}/task"))
        seen = scheduling(proc.pid)
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = finish(proc, timeout=60)
    assert proc.returncode == 0, err[-2000:]
    assert threads > 1 and seen == expected, seen
    assert (bag / "metadata.yaml").is_file()


def test_a_niceness_out_of_range_is_one_line_and_exit_2(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "stillframe", "record", "-o",
                           str(tmp_path / "bag"), "--all", "--nice", "20"], env=child_env(),
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "stillframe record: error: argument --nice: 20: must lie in [0, 19] "
        "(see stillframe record -h)"]
