"""Writer identity on the loop's sensor topics (issue 11): a stray simulator, a real rclpy peer
(when rclpy is installed) and a Cyclone writer of ours, writes plausible samples on every sensor
topic of a lock-step LQG run, stamped with the loop's own ``/clock``. The estimator and the
controller take their inputs from the simulator's writers only, so the run equals the
one-process loop to the last bit; every sample the strays wrote is refused and counted (their
counts against the nodes' ``/diagnostics``), and the strays are named there. Both ways to say
which writer is the simulator: the first seen (the strays start at the loop's second sample,
after the simulator's first one has been taken: the loop cannot get there before), and
``sensor_writer:=sim_node`` (the strays from the first sample on).
"""

from __future__ import annotations

import importlib.util
import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from stillframe.contract.codecs import SENSOR_TOPICS
from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.loop.writer_gate import REASONS
from stillframe.middleware.api import create_node, spin_until
from tests.support.middleware import child_env, finish, wait_for_line
from tests.support.nodes import SHORT_LQG, Statuses, params_file, start_node, stop
from tests.support.scenes import thesis_scene
from tests.support.waits import HANG_S

STRAY = REPO_ROOT / "tests" / "support" / "stray_sensors.py"
BACKENDS = ("rclpy", "dds") if importlib.util.find_spec("rclpy") else ("dds",)


def refused(values: dict[str, str], topic: str) -> int:
    key = topic.replace("/", "_")
    return sum(int(values.get(f"{key}_rejected_{r}", 0)) for r in REASONS)


@pytest.mark.slow
@pytest.mark.parametrize("sensor_writer", ["", "sim_node"])
def test_stray_simulator_is_ignored_counted_and_named(ros_domain: int, tmp_path: Path,
                                                       sensor_writer: str) -> None:
    result = tmp_path / "result.json"
    params = params_file(tmp_path, "thesis_lqg", SHORT_LQG, result_file=str(result),
                         command_writer="controller_node", sensor_writer=sensor_writer,
                         diagnostics_period_s=0.2)
    from_s = "0" if sensor_writer else "0.05"         # the second sample (32 Hz)
    strays = [subprocess.Popen([sys.executable, str(STRAY), backend, from_s], env=child_env(),
                               cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True) for backend in BACKENDS]
    assert all(wait_for_line(s, "ready") for s in strays)
    peers = [start_node(name, params) for name in ("estimator_node", "controller_node")]
    sim = start_node("sim_node", params)
    probe = create_node("identity_probe", argv=["test"])
    statuses = Statuses(probe)
    sent: list[int] = []

    def latest(node: str) -> dict[str, str]:
        return statuses.latest.get(f"/frame/{node}", (0, "", {}))[2]

    try:
        assert spin_until(probe, lambda: sim.poll() is not None, HANG_S)
        for s in strays:
            s.send_signal(signal.SIGTERM)
            out, err = finish(s, timeout=60)
            assert s.returncode == 0, err[-2000:]
            sent.append(int(out.split()[-1]))
        total = sum(sent)
        # every sample written reached the loop's reliable readers: wait until all are counted
        spin_until(probe, lambda: (
            sum(refused(latest("estimator_node"), s.name) for s in SENSOR_TOPICS) == 5 * total
            and refused(latest("controller_node"), "excitation/wrench") == total), 60)
        level, message, est = statuses.latest["/frame/estimator_node"]
        ctl = latest("controller_node")
    finally:
        probe.destroy_node()
        codes = [stop(p) for p in peers]
        for proc in (sim, *strays):
            if proc.poll() is None:
                stop(proc)
    assert sim.returncode == 0 and all(code == 0 for code, _ in codes)
    print(f"stray stamps written ({', '.join(BACKENDS)}): {sent}; estimator refused",
          {s.name: {r: est[f"{s.name.replace('/', '_')}_rejected_{r}"] for r in REASONS}
           for s in SENSOR_TOPICS}, "; ignored:", est["floor1_imu_ignored_writers"])
    assert all(n > 0 for n in sent)
    for spec in SENSOR_TOPICS:                      # each stray sample refused, on every topic
        assert refused(est, spec.name) == total, spec.name
        assert est[f"{spec.name.replace('/', '_')}_writer"] == "/frame/sim_node"
        ignored = est[f"{spec.name.replace('/', '_')}_ignored_writers"].split(",")
        assert "/frame/stray_sensors_dds" in ignored
        # the rclpy peer by name, or by its writer GID while the graph has not named the Fast
        # DDS participant yet (the only eProsima, vendor 01.0f, writer)
        assert len(ignored) == len(BACKENDS) and all(
            name.startswith("/frame/stray_sensors_") or name.startswith("010f")
            for name in ignored), ignored
    assert int(est["refused_writers"]) == 5 * total and int(ctl["refused_writers"]) == total
    assert ctl["excitation_wrench_writer"] == "/frame/sim_node"
    # a warning; an error only once the simulator has gone long enough for the input to be stale
    assert level == (2 if "stale input" in message else 1), message
    assert "second writer on floor1/imu ignored" in message, message
    reference = run_closed_loop(thesis_scene("thesis_lqg", SHORT_LQG))
    evaluation = json.loads(result.read_text())
    with np.load(result.with_suffix(".npz")) as data:
        np.testing.assert_array_equal(data["truth"], reference.truth)
        np.testing.assert_array_equal(data["command"], reference.command)
    assert evaluation["reduction_pct"] == reference.evaluation["reduction_pct"]
    assert evaluation["complete"] is True
