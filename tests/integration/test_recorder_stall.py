"""A stalled recorder says so and counts what the bag misses: ``launch --record`` in real time,
the launch's recorder stopped (SIGSTOP) while the simulator runs 3 s of its time, then resumed
(SIGCONT), on both backends.

The stall is forced, not timed: the test follows the simulator's ``/clock`` itself and stops the
recorder once sampling runs, resumes it once the simulator has gone 3 s (3072 samples of every
topic at 1024 Hz, megabytes: more than the sockets and the publishers' histories keep for a
stopped reader). What the bag lacks is counted independently of the recorder, each per-step
topic's stamps read back by rosbags: against every sample time from its first to its last (the
stamp grid's gaps, which the recorder counts), and against the 6144 samples the scene's 6 s at
1024 Hz make (every sample the bag does not hold, which the launch counts from the simulator's
own count). Those counts must be the recorder's and the launch's, per topic, in the recorder's
last line, in ``metadata.yaml``'s custom data (plain PyYAML) and in launch's JSON; launch ends
with a warning line, and so does ``bag info`` of the bag; the stall is logged while the recorder
runs.

Two outcomes are both right, and the test takes either. Under Cyclone DDS (and often under Fast
DDS) the samples sent during the stop are lost in the middle of the bag: a gap in the stamp grid.
Under Fast DDS the shared-memory transport can instead mark the stopped reader's port as dead
after its health check: the simulator's writes then wait on that port (3 s of sim time took 9
to 21 s of wall time here) and the recorder receives nothing more from the simulator after its
stop. Those samples lie after the last stamp the bag holds, so no grid shows them: the launch's
count against the simulator's does.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml
from rosbags.highlevel import AnyReader

from stillframe.contract.topics import PER_SAMPLE
from stillframe.locations import REPO_ROOT
from stillframe.middleware import api
from stillframe.recording.recorder import MISSING_KEY, STALLS_KEY
from tests.support.middleware import child_env
from tests.support.waits import HANG_S

pytestmark = pytest.mark.slow

SCENE = REPO_ROOT / "scenes" / "thesis_lqg.yaml"
#: the scene's integrator step divides 1/1024 s; a period that is no whole number of ns (its
#: stamps are rounded: the recorder's grid takes that)
RATE_HZ = 1024
PERIOD_NS = 1e9 / RATE_HZ
#: sim time before the stop, and sim time the simulator runs while the recorder is stopped [s]
BEFORE_S, STALLED_S = 1.0, 3.0
OVERRIDES = ["--set", f"sensors.rate_hz={RATE_HZ}", "--set", "duration=6", "--set",
             "controller.start=3", "--set", "evaluation.window=2"]
#: the samples of the scene's 6 s at 1024 Hz, one message each on every per-step topic
STEPS = 6 * RATE_HZ
#: a bound against a hung run, not a timing assertion [s]
WAIT_S = 600.0
#: the recorder's own code is the same on both; rclpy's recorder at 1 kHz runs by default in
#: test_recorder_complete, so its stall here is long
BACKENDS = [pytest.param(b, marks=[pytest.mark.skipif(b == "rclpy" and not api.has_rclpy(),
                                                      reason="rclpy not installed"),
                                   *([pytest.mark.long] if b == "rclpy" else [])])
            for b in api.BACKENDS]


class Lines:
    """The launch's stderr, read by a thread, kept whole."""

    def __init__(self, stream: object) -> None:
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream: object) -> None:
        for line in stream:   # type: ignore[attr-defined]
            self.lines.append(line.rstrip("\n"))

    def find(self, pattern: str) -> re.Match | None:
        return next((m for line in list(self.lines) if (m := re.search(pattern, line))), None)

    def join(self) -> str:
        self._thread.join(timeout=HANG_S)
        return "\n".join(self.lines)


def sample_indices(bag: Path) -> dict[str, list[int]]:
    """Per per-step topic, the sample index of each of its messages (its stamp over the
    period), read back by rosbags message by message."""
    held: dict[str, list[int]] = {topic: [] for topic in PER_SAMPLE}
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages([c for c in reader.connections
                                             if c.topic in PER_SAMPLE]):
            msg = reader.deserialize(raw, conn.msgtype)
            stamp = msg.clock if conn.topic == "/clock" else msg.header.stamp
            held[conn.topic].append(
                round((stamp.sec * 1_000_000_000 + stamp.nanosec) / PERIOD_NS))
    return held


def missing_in(held: dict[str, list[int]]) -> dict[str, int]:
    """Per topic with samples, the sample times from its first to its last that it lacks."""
    return {topic: max(k) - min(k) + 1 - len(set(k)) for topic, k in held.items() if k}


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_stopped_recorder_counts_what_the_bag_misses(tmp_path: Path, ros_domain: int,
                                                        backend: str) -> None:
    bag = tmp_path / "bag"
    launch = subprocess.Popen(
        [sys.executable, "-m", "stillframe", "launch", str(SCENE), *OVERRIDES, "--mode",
         "realtime", "--backend", backend, "--record", str(bag), "--json"],
        env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    err = Lines(launch.stderr)
    probe = api.create_node(f"stall_probe_{os.getpid()}", argv=["probe"], backend=backend)
    sim_ns = [0]
    probe.create_subscription("rosgraph_msgs/msg/Clock", "/clock", lambda m: sim_ns.__setitem__(
        0, max(sim_ns[0], m.clock.sec * 1_000_000_000 + m.clock.nanosec)), "sensor_data")

    def spin_until(done: object) -> None:
        deadline = time.monotonic() + WAIT_S
        while not done():   # type: ignore[operator]
            assert launch.poll() is None, err.join()[-3000:]
            assert time.monotonic() < deadline, err.join()[-3000:]
            probe.spin_once(0.05)

    try:
        spin_until(lambda: err.find(r"started recorder \(pid (\d+)\)") is not None)
        recorder = int(err.find(r"started recorder \(pid (\d+)\)").group(1))
        spin_until(lambda: sim_ns[0] >= BEFORE_S * 1e9)
        os.kill(recorder, signal.SIGSTOP)
        stopped_at = sim_ns[0]
        try:
            spin_until(lambda: sim_ns[0] >= stopped_at + STALLED_S * 1e9)
        finally:
            os.kill(recorder, signal.SIGCONT)
        out = launch.stdout.read()     # stderr is the reader thread's
        launch.wait(timeout=WAIT_S)
    finally:
        probe.destroy_node()
        if launch.poll() is None:
            launch.kill()
            launch.wait()
    text = err.join()
    assert launch.returncode == 0, text[-3000:]
    held = sample_indices(bag)
    missing = missing_in(held)
    doc = json.loads(out)["bag"]
    assert json.loads(out)["steps"] == STEPS
    assert doc["not_recorded"] == {topic: STEPS - len(k) for topic, k in held.items()}
    assert sum(doc["not_recorded"].values()) > 0, doc
    counted = doc["missing_samples"]
    assert {t: counted[t] for t in missing} == missing
    custom = yaml.safe_load((bag / "metadata.yaml").read_text())[
        "rosbag2_bagfile_information"]["custom_data"]
    assert json.loads(custom[MISSING_KEY]) == counted
    assert json.loads(custom[STALLS_KEY]) == doc["recorder_stalls"]
    # the stop lasted at least the wall time of 3 s of real-time simulation
    assert doc["recorder_stalls"]["count"] >= 1
    assert doc["recorder_stalls"]["longest_s"] >= 1.0
    total = sum(n for n in counted.values())
    beyond = sum(doc["not_recorded"][t] - counted.get(t, 0) for t in PER_SAMPLE)
    assert re.search(r"\[recorder\] .*recorder stalled: no poll for", text), text[-3000:]
    said = rf"stillframe launch: warning: the bag {re.escape(str(bag))} is not complete: "
    if total:
        assert re.search(rf"\[recorder\] .*the bag is not complete: it misses {total} samples",
                         text)
        assert re.search(said + rf"it misses {total} samples", text)
    else:
        assert re.search(r"\[recorder\] .*the bag may not be complete: the recorder stalled",
                         text)
    if beyond:
        assert re.search(said + rf"(it misses .*; )?it lacks {beyond} more samples the "
                                "simulator published", text), text[-3000:]
    info = subprocess.run([sys.executable, "-m", "stillframe", "bag", "info", str(bag)],
                          env=child_env(), cwd=REPO_ROOT, capture_output=True, text=True,
                          timeout=WAIT_S)
    assert info.returncode == 0, info.stderr
    assert (f"warning: the recorder found {total} samples missing" in info.stderr) == (total > 0)
