"""``launch --mode realtime --track``'s tracker runs at SCHED_IDLE (issue 27 must show 5: it
cannot delay the loop): every thread of the process the launcher starts (:func:`tracker_command`;
the identification worker, started later, inherits the policy), and it stops cleanly on SIGINT."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

from stillframe.app.tracking import tracker_command
from stillframe.config.scene import load_scene
from stillframe.locations import REPO_ROOT
from tests.support.middleware import child_env, scheduling


def test_the_idle_tracker_runs_at_sched_idle(tmp_path: Path, ros_domain: int) -> None:
    scene = load_scene(REPO_ROOT / "scenes" / "thesis_lqg.yaml")
    argv = tracker_command(scene, tmp_path / "tracked.jsonl", lockstep=False)
    proc = subprocess.Popen(argv, env=child_env(), cwd=REPO_ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        # idle once the node has read its parameters (imports and node creation come first)
        while {policy for policy, _ in scheduling(proc.pid)} != {os.SCHED_IDLE}:
            assert proc.poll() is None and time.monotonic() < deadline, scheduling(proc.pid)
            time.sleep(0.2)
        # the middleware's threads too, not only the main one
        assert len(os.listdir(f"/proc/{proc.pid}/task")) > 1
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err[-2000:]


def test_a_wrong_tracker_parameter_is_one_line_and_exit_2(tmp_path: Path, ros_domain: int) -> None:
    """The tracker's parameters are declared as data (``TrackerParameterValues``): a wrong one
    is refused with its name and the rule it breaks, exit code 2, as for the loop's nodes."""
    scene = load_scene(REPO_ROOT / "scenes" / "thesis_lqg.yaml")
    argv = [*tracker_command(scene, tmp_path / "tracked.jsonl", lockstep=True),
            "-p", "window_s:=-1.0"]
    done = subprocess.run(argv, env=child_env(), cwd=REPO_ROOT, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2, done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if "error" in line]
    assert errors == ["node.py: error: parameter 'window_s': must be > 0 (got -1.0)"], errors
