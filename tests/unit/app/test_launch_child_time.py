"""The launcher's lifecycle timeout counts the time the machine gave a child
(:meth:`Child.time_given_s`): wall time less the run-queue wait of its main thread
(:meth:`Child.waited_s`). A child that sleeps (or hangs) uses its time up, so the timeout still
ends a hung start.

Its start-up may wait for a CPU on a busy machine, so the test looks from the moment the kernel
shows the child asleep: a sleeping thread is on no run queue, so its wait does not grow however
busy the machine is.

A starved child's case is not held here: a busy child at SCHED_IDLE pinned beside busy loops
showed its run-queue wait in ``/proc/PID/schedstat`` in some runs and not in others (with
autogroup scheduling on), so a bound on it would fail by chance."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from stillframe.app.launcher import Child

SLEEPER = "import time; print('sleeping', flush=True); time.sleep(60)"


def state(pid: int) -> str:
    """The kernel's one-letter state of a process (``/proc/PID/stat``, after the name)."""
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]


def test_a_sleeping_child_is_given_its_wall_time() -> None:
    child = Child("probe", subprocess.Popen([sys.executable, "-c", SLEEPER],
                                            stdout=subprocess.PIPE, text=True))
    try:
        assert child.proc.stdout.readline() == "sleeping\n"
        while state(child.pid) != "S":     # past the print, in its sleep
            time.sleep(0.01)
        waited = child.waited_s()
        time.sleep(1.0)
        assert child.waited_s() - waited <= 1e-3
        # what it was given is the wall time less that wait, up to the clock's later read
        given = child.time_given_s()
        wall = (time.monotonic_ns() - child.started_ns) * 1e-9
        assert 0.0 <= wall - child.waited_s() - given <= 0.5
    finally:
        child.proc.kill()
        child.proc.wait()
