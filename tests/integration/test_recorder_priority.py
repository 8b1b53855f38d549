"""``stillframe record --nice N --idle`` (issue 32): the recorder steps back from the loop's nodes
for CPU time, and every thread it starts (the middleware's receive threads, the bag's writer)
inherits that; the kernel's view of each thread (``/proc``) is the independent check."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from stillframe.locations import REPO_ROOT
from tests.support.middleware import child_env, finish, niced, scheduling, wait_for_line


@pytest.mark.parametrize(("args", "policy", "increment"), [
    (["--nice", "7"], os.SCHED_OTHER, 7),
    (["--nice", "3", "--idle"], os.SCHED_IDLE, 3),
])
def test_every_recorder_thread_runs_at_the_priority_asked(
        tmp_path: Path, ros_domain: int, args: list[str], policy: int, increment: int) -> None:
    """Every thread at the niceness asked, and at SCHED_IDLE with ``--idle`` from the ready line
    on (the set-up runs at the niceness only: an idle process gets next to no CPU time beside
    busy ones, and the launch waits for the line), and a clean stop with the bag closed: an
    idle recorder leaves SCHED_IDLE when asked to stop, so it closes its bag however busy the
    machine (the suite runs this beside two busy loops)."""
    bag = tmp_path / "bag"
    proc = subprocess.Popen([sys.executable, "-m", "stillframe", "record", "-o", str(bag), "--all",
                             *args], env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        wait_for_line(proc, "Recording to", timeout=120)
        threads = len(os.listdir(f"/proc/{proc.pid}/task"))
        seen = scheduling(proc.pid)
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = finish(proc, timeout=60)
    assert proc.returncode == 0, out[-2000:]
    assert threads > 1 and seen == {(policy, niced(increment))}, seen
    assert (bag / "metadata.yaml").is_file()


def test_a_niceness_out_of_range_is_one_line_and_exit_2(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "stillframe", "record", "-o",
                           str(tmp_path / "bag"), "--all", "--nice", "20"], env=child_env(),
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "stillframe record: error: argument --nice: 20: must lie in [0, 19] "
        "(see stillframe record -h)"]


def recorder_pid(bag: Path) -> int | None:
    """The process recording into ``bag`` (``stillframe record -o BAG``), if one runs."""
    for entry in os.listdir("/proc"):
        try:
            argv = Path(f"/proc/{entry}/cmdline").read_bytes().split(b"\0")
        except (OSError, ValueError):
            continue
        if b"record" in argv and str(bag).encode() in argv:
            return int(entry)
    return None


def test_launch_hands_its_recorder_the_priority_asked(tmp_path: Path, ros_domain: int) -> None:
    """``launch --record DIR --recorder-nice 5 --recorder-idle``: the recorder the launcher
    starts runs every thread at SCHED_IDLE and nice 5 (the kernel's view) from its ready line
    on, which the launch waits for before it starts the nodes (the bag is open before that, at
    the niceness only), and the run ends with its bag closed."""
    bag = tmp_path / "bag"
    launch = subprocess.Popen(
        [sys.executable, "-m", "stillframe", "launch", "thesis_lqg", "--set", "duration=2",
         "--set", "controller.start=1", "--set", "evaluation.window=0.5", "--record", str(bag),
         "--recorder-nice", "5", "--recorder-idle", "--json"],
        env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True)
    try:
        wait_for_line(launch, "Recording to", timeout=120)
        pid = recorder_pid(bag)
        seen = scheduling(pid) if pid is not None else set()
        out, _ = finish(launch, timeout=300)
    finally:
        if launch.poll() is None:
            launch.kill()
    assert launch.returncode == 0, out[-2000:]
    assert seen == {(os.SCHED_IDLE, niced(5))}, seen
    assert (bag / "metadata.yaml").is_file()
