"""``launch --mode realtime --track``'s tracker runs at SCHED_IDLE (issue 27 must show 5: it
cannot delay the loop): every thread of the process the launcher starts (:func:`tracker_command`;
the identification worker, started later, inherits the policy), and it stops cleanly on SIGINT;
stopped twice, it loses no window in silence."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from identification.node import READ_DEPTH
from stillframe.app.tracking import given_up, read_tracked, tracker_command
from stillframe.config.scene import load_scene
from stillframe.contract import messages, topics
from stillframe.identification.tracker import EXIT_GIVEN_UP, GIVEN_UP, TRACKER_READY
from stillframe.locations import REPO_ROOT
from stillframe.middleware.api import create_node, spin_until
from stillframe.middleware.qos import SENSOR_DATA, Durability, Reliability
from tests.support.middleware import child_env, finish, scheduling, wait_for_line
from tests.support.waits import HANG_S


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


def test_a_tracker_stopped_twice_writes_each_window_due_as_given_up(tmp_path: Path,
                                                                    ros_domain: int) -> None:
    """A lock-step tracker keeps every due window (``reliable``); stopped once it identifies
    them all, stopped again meanwhile (the launch's SIGTERM after its grace) it ends at once with
    ``EXIT_GIVEN_UP`` and writes each window still due as an update whose error says it was
    given up: the record then holds every due window once, identified or given up, a whole
    number of update periods apart (nothing lost in silence), and the launch's warning counts
    the given-up ones. Forced: 64 windows of 256 samples are due when the second signal comes
    half a second after the first, far more than any machine identifies in that time."""
    scene = load_scene(REPO_ROOT / "scenes" / "thesis_lqg.yaml")
    record = tmp_path / "tracked.jsonl"
    period, rate = 0.25, scene.sensors.rate_hz
    argv = [*tracker_command(scene, record, lockstep=True), "-p", "window_s:=8.0",
            "-p", f"update_period_s:={period}"]
    proc = subprocess.Popen(argv, env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    probe = None
    try:
        wait_for_line(proc, TRACKER_READY, timeout=120)
        probe = create_node("probe", namespace=topics.DEFAULT_NAMESPACE, argv=["test"])
        qos = replace(SENSOR_DATA, reliability=Reliability.RELIABLE,
                      durability=Durability.TRANSIENT_LOCAL, depth=READ_DEPTH)
        wrench = probe.create_publisher(topics.EXCITATION_WRENCH.type_name,
                                        topics.EXCITATION_WRENCH.name, qos)
        imus = [probe.create_publisher(spec.type_name, spec.name, qos)
                for spec in topics.FLOOR_IMU]
        assert spin_until(probe, lambda: all(p.get_subscription_count() > 0
                                             for p in (wrench, *imus)), HANG_S)
        rng = np.random.default_rng(0)
        load, imu = (messages.new("geometry_msgs/msg/WrenchStamped"),
                     messages.new("sensor_msgs/msg/Imu"))
        samples = round((8.0 / 2 + 64 * period) * rate)
        for k in range(samples):
            stamp = messages.time_msg(round(k / rate * 1e9))
            load.header.stamp = imu.header.stamp = stamp
            load.wrench.force.x = float(rng.standard_normal())
            wrench.publish(load)
            for publisher in imus:
                imu.linear_acceleration.x = float(rng.standard_normal())
                publisher.publish(imu)
            if k % 32 == 31:
                spin_until(probe, lambda: False, 0.05)   # paced: within the readers' depth
        while not record.exists() and proc.poll() is None:
            spin_until(probe, lambda: False, 0.1)       # the first window is being identified
        proc.send_signal(signal.SIGINT)
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        out, _ = finish(proc, timeout=120)
    finally:
        if probe is not None:
            probe.destroy_node()
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == EXIT_GIVEN_UP, out[-2000:]
    tracked = read_tracked(record)
    lost = [u for u in tracked if (u["error"] or "").startswith(GIVEN_UP)]
    assert lost and lost == tracked[len(tracked) - len(lost):], out[-2000:]
    assert f"windows still due, given up: {len(lost)} " in out, out[-2000:]
    times = np.array([u["t"] for u in tracked])
    assert np.allclose(np.diff(times), period, atol=1e-9), times
    warning = given_up(tracked)
    assert warning.startswith("the modal tracker gave up the windows due at its stop (t = ")
    assert warning.count(",") == len(lost) - 1, warning      # each given-up window's time
