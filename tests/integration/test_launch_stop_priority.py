"""A recorder that ran below the loop (SCHED_IDLE, niced) is put back at the launcher's
scheduling before it is asked to stop, so a busy machine cannot starve it past its grace and kill
it with its bag open. The condition is forced: one busy loop per CPU beside a child at SCHED_IDLE
and nice 5 whose SIGINT handler needs 0.1 s of CPU (as closing a small bag does). At SCHED_IDLE
its share would be about 0.3 % of a CPU (weight 3 against the busy loops' 1024 each), half a
minute for the handler, past the launcher's first grace (10 s), after which SIGTERM ends it;
put back, it ends on its own handler with exit code 0. The handler is short so that it also
finishes within that grace when other work shares the machine (a whole CPU's worth of 0.1 s
is had in 10 s beside 200 busy tasks at the same weight)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import pytest

from stillframe.app.launcher import ProcessSet
from stillframe.node_runtime.realtime import CAP_SYS_NICE, capable

pytestmark = pytest.mark.skipif(not capable(CAP_SYS_NICE),
                                reason="leaving SCHED_IDLE needs CAP_SYS_NICE")

#: the child: below the loop, with a handler that needs CPU time to finish
CHILD = """
import signal, sys, time
from stillframe.node_runtime.realtime import run_idle, run_nicer
run_nicer(5)      # as `stillframe record --nice 5 --idle` steps back
run_idle()
def close(*_):
    end = time.thread_time() + 0.1
    while time.thread_time() < end:
        pass
    sys.exit(0)
signal.signal(signal.SIGINT, close)
print("ready", flush=True)
while True:
    time.sleep(0.05)
"""


def test_a_recorder_below_the_loop_closes_on_its_own_handler_on_a_busy_machine() -> None:
    ready = threading.Event()
    lines: list[str] = []

    def echo(line: str) -> None:
        lines.append(line)
        if line.endswith("] ready"):
            ready.set()

    processes = ProcessSet(echo)
    child = processes.start("recorder", [sys.executable, "-c", CHILD], restore_on_stop=True)
    busy = []
    try:
        assert ready.wait(120), lines
        busy = [subprocess.Popen(["sh", "-c", "while :; do :; done"])
                for _ in os.sched_getaffinity(0)]
        processes.stop(child)
    finally:
        for loop in busy:
            loop.kill()
            loop.wait()
        if child.proc.poll() is None:
            child.proc.kill()
    assert child.proc.returncode == 0, lines
