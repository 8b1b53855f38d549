"""The launcher's lifecycle timeout counts the time the machine gave a child
(:meth:`Child.time_given_s`): wall time less the run-queue wait of its main thread. A child that
sleeps (or hangs) uses its time up, so the timeout still ends a hung start.

A starved child's case is not held here: a busy child at SCHED_IDLE pinned beside busy loops
showed its run-queue wait in ``/proc/PID/schedstat`` in some runs and not in others (with
autogroup scheduling on), so a bound on it would fail by chance."""

from __future__ import annotations

import subprocess
import sys
import time

from stillframe.app.launcher import Child


def test_a_sleeping_child_is_given_its_wall_time() -> None:
    child = Child("probe", subprocess.Popen([sys.executable, "-c",
                                             "import time; time.sleep(60)"]))
    try:
        time.sleep(1.0)
        wall = (time.monotonic_ns() - child.started_ns) * 1e-9
        given = child.time_given_s()
        # never more than the wall time; less only by its start-up's wait for a CPU
        assert 0.5 * wall <= given <= wall + 0.05
    finally:
        child.proc.kill()
        child.proc.wait()
