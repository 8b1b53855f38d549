"""The pH plant's energy balance on ``energy_balance`` through the three node processes,
recorded by ``launch --record`` and read back with the ``mcap`` library and rosbags' type store
(independent of the project's bag reader): the published powers integrate to ΔH to round-off,
and ``/diagnostics`` reports the passivity controller's energy as the bag's powers give it — and
a violation when an actuation delay makes the sampled law supply energy."""

from __future__ import annotations

import asyncio
import json
import re
import subprocess
import sys
import threading
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from stillframe.contract import topics
from stillframe.contract.messages import TYPESTORE
from stillframe.locations import REPO_ROOT
from stillframe.monitor.foxglove_client import Capture, capture
from tests.support.middleware import child_env, run_stillframe
from tests.support.waits import HANG_S

SHORT = ["duration=3", "controller.start=1", "evaluation.window=1"]
WARN = 1


def launch_and_read(tmp_path: Path, extra: list[str]) -> tuple[np.ndarray, dict, list[str]]:
    bag = tmp_path / "bag"
    sets = [a for o in [*SHORT, *extra] for a in ("--set", o)]
    done = run_stillframe("launch", "scenes/ph_passivity.yaml", *sets, "--record", str(bag),
                          "--json", timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout)
    assert result["steps"] == 96
    rows, labels, status = [], set(), None
    with next(bag.glob("*.mcap")).open("rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            if channel.topic == "/frame/" + topics.ENERGY_BALANCE.name:
                msg = TYPESTORE.deserialize_cdr(message.data, schema.name)
                rows.append(np.array(msg.data))
                labels.add(msg.layout.dim[0].label)
            elif channel.topic == "/diagnostics":
                msg = TYPESTORE.deserialize_cdr(message.data, schema.name)
                for s in msg.status:
                    if s.name.endswith("sim_node"):
                        status = (s.level, s.message, {kv.key: kv.value for kv in s.values})
    # the launch's result carries the sim's last balance and check, as /diagnostics did
    values = status[2]
    final = result["energy_balance"]
    assert final["passivity_violations"] == int(values["passivity_violations"])
    assert final["energy_stored_J"] == pytest.approx(rows[-1][1], rel=1e-12)
    return np.array(rows), status, sorted(labels)


def recomputed_violations(rows: np.ndarray, start: float) -> tuple[float, int]:
    """The controller's energy and the samples where it exceeds what k_p = 0 allows (nothing),
    from the bag's powers alone."""
    T = rows[1, 0] - rows[0, 0]
    after = rows[:, 0] > start          # periods from the controller's start on
    supplied = np.cumsum(T * rows[after, 3])
    largest = np.maximum.accumulate(np.abs(rows[:, 1]))[after]
    return float(supplied[-1]), int(np.sum(supplied > 1e-9 * largest + 1e-15))


@pytest.mark.slow
def test_published_powers_integrate_to_the_stored_energy_and_diagnostics_agree(
        ros_domain: int, tmp_path: Path) -> None:
    rows, status, labels = launch_and_read(tmp_path, [])
    assert labels == [",".join(topics.ENERGY_FIELDS)]
    T = 1 / 32
    np.testing.assert_allclose(rows[:, 0], np.arange(len(rows)) * T, rtol=0, atol=1e-12)
    assert np.all(rows[0, 2:] == 0)
    supplied = T * (rows[1:, 2] + rows[1:, 3] + rows[1:, 4] - rows[1:, 5])
    scale = np.max(np.abs(rows[:, 1]))
    # per sample and over the run: ΔH = ∫(P_excitation + P_actuator + P_noise − P_dissipated).
    # A sample is 8 AVF steps, each balanced to a few u·H, plus the rounding of two stored H and
    # four powers: ≲ 100u·H (bound 900u); the run adds the samples' errors. The dissipation alone
    # moves ≈ 2 % of H per sample, so a wrong port term is far above either bound.
    assert np.max(np.abs(supplied - np.diff(rows[:, 1]))) < 1e-13 * scale
    assert abs(supplied.sum() - (rows[-1, 1] - rows[0, 1])) < len(supplied) * 1e-13 * scale
    assert np.all(rows[1:, 5] > 0) and np.any(rows[:, 3] != 0)
    level, message, values = status
    energy, violations = recomputed_violations(rows, 1.0)
    assert float(values["controller_energy_J"]) == pytest.approx(energy, rel=1e-5)
    assert int(values["passivity_violations"]) == violations == 0
    assert level == 0 and "passivity" not in message


@pytest.mark.slow
def test_diagnostics_report_a_controller_supplying_energy(ros_domain: int,
                                                         tmp_path: Path) -> None:
    """One period of actuation delay turns the damping injection into an energy source at the
    pendulum's frequency: the controller's port supplies energy its storage never held."""
    rows, status, _ = launch_and_read(tmp_path, ["actuators.delay_periods=1"])
    level, message, values = status
    energy, violations = recomputed_violations(rows, 1.0)
    assert energy > 0 and violations > 0
    assert int(values["passivity_violations"]) == violations
    assert float(values["controller_energy_J"]) == pytest.approx(energy, rel=1e-5)
    assert level == WARN and message.startswith("passivity: the controller supplied")


MONITOR_READY = re.compile(r"Monitor ready: foxglove (ws://\S+?), dashboard (http://\S+)$")


@pytest.mark.slow
@pytest.mark.long   # the monitor's transport runs by default in test_monitor; the balance's
                    # numbers in test_published_powers_integrate_to_the_stored_energy…
def test_energy_balance_reaches_foxglove_and_the_dashboard(ros_domain: int) -> None:
    """A real-time launch with the monitor: a foxglove.websocket client decodes
    ``energy_balance`` with the advertised ros2msg schema (the layout label included), and the
    dashboard's ``/data`` serves its series (H and four powers against t_k)."""
    topic = "/frame/" + topics.ENERGY_BALANCE.name
    sets = [a for o in ["duration=6", "controller.start=2", "evaluation.window=2"]
            for a in ("--set", o)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "stillframe", "launch", "scenes/ph_passivity.yaml", *sets,
         "--mode", "realtime", "--monitor", "--monitor-port", "0", "--dashboard-port", "0",
         "--no-monitor-idle", "--json"],
        env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    urls = None
    for line in proc.stderr:
        if (found := MONITOR_READY.search(line.rstrip())) is not None:
            urls = found[1], found[2]
            break
    assert urls is not None
    threading.Thread(target=proc.stderr.read, daemon=True).start()

    async def watch() -> tuple[Capture, dict]:
        done, seen = asyncio.Event(), Capture()
        task = asyncio.create_task(capture(urls[0], [topic], done, seen))
        data: dict = {}
        while proc.poll() is None:
            await asyncio.sleep(0.5)
            try:
                with urllib.request.urlopen(urls[1] + "data", timeout=HANG_S) as response:
                    data = json.loads(response.read())["series"]["energy"]
            except OSError:    # the monitor stops with the launch: keep the last answer
                break
        done.set()
        await task
        return seen, data

    try:
        seen, series = asyncio.run(watch())
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=60)
    channel = seen.channels[topic]
    assert (channel["schemaName"], channel["encoding"]) == ("std_msgs/msg/Float64MultiArray",
                                                            "cdr")
    got = seen.messages.get(topic, [])
    assert len(got) >= 10
    assert got[0].layout.dim[0].label == ",".join(topics.ENERGY_FIELDS)
    t = [float(m.data[0]) for m in got]
    assert all(abs(k * 32 - round(k * 32)) < 1e-9 for k in t)     # sample times k / 32
    assert len(series["y"]) == len(topics.ENERGY_FIELDS) - 1 and len(series["t"]) >= 5
    assert all(abs(x * 32 - round(x * 32)) < 1e-9 for x in series["t"])
