"""``stillframe monitor`` during real launches: a real ``foxglove.websocket.v1`` client against
the recorder's bag, slow and churning clients, and the dashboard in headless Chromium."""

from __future__ import annotations

import asyncio
import itertools
import json
import re
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field

import pytest

from stillframe import messages
from stillframe.bags import read_bag
from tests.foxglove_client import Capture, capture, churn, stall
from tests.mw_support import REPO_ROOT, child_env, isolate_domain

pytestmark = pytest.mark.slow

SCENE = REPO_ROOT / "scenes" / "thesis_lqg.yaml"
#: 12 s of the LQG scene at 32 Hz: control from 6 s, peaks over 6 s windows
SHORT = ["--set", "duration=12", "--set", "controller.start=6", "--set", "evaluation.window=6"]
IMU = "/frame/floor1/imu"
READY = re.compile(r"Monitor ready: foxglove (ws://\S+?)(?:, dashboard (http://\S+))?$")


@dataclass
class Launch:
    """A ``stillframe launch --monitor`` child whose stderr is read by a thread."""

    proc: subprocess.Popen
    lines: list[str] = field(default_factory=list)
    ready: threading.Event = field(default_factory=threading.Event)
    urls: tuple[str, str | None] = ("", None)

    @classmethod
    def start(cls, *args: str) -> Launch:
        proc = subprocess.Popen(
            [sys.executable, "-m", "stillframe", "launch", str(SCENE), "--monitor",
             "--monitor-port", "0", "--dashboard-port", "0", *args],
            env=child_env(), cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True)
        launch = cls(proc)
        threading.Thread(target=launch._read, daemon=True).start()
        assert launch.ready.wait(120), "".join(launch.lines[-30:])
        return launch

    def _read(self) -> None:
        for line in self.proc.stderr:
            self.lines.append(line)
            if (found := READY.search(line.rstrip())) is not None:
                self.urls = (found[1], found[2])
                self.ready.set()
        self.ready.set()

    def finish(self, timeout: float = 180) -> dict:
        out, _ = self.proc.communicate(timeout=timeout)
        assert self.proc.returncode == 0, "".join(self.lines[-30:])
        return json.loads(out)


@pytest.fixture(scope="module")
def lockstep_run(tmp_path_factory: pytest.TempPathFactory, ros_domain_module: int) -> dict:
    """One lock-step launch with the monitor and a recorder of the IMU topic and ``/clock``;
    meanwhile a subscribing client, a client that stops reading, and clients that come and
    go."""
    bag = tmp_path_factory.mktemp("monitor") / "bag"
    launch = Launch.start(*SHORT, "--json", "--record", str(bag), "--record-topic", IMU,
                          "--record-topic", "/clock")
    url = launch.urls[0]

    async def clients() -> tuple[Capture, int, int]:
        done = asyncio.Event()
        seen = Capture()
        tasks = [asyncio.create_task(capture(url, [IMU], done, seen)),
                 asyncio.create_task(stall(url, IMU, done)),
                 asyncio.create_task(churn(url, done))]
        await asyncio.to_thread(launch.proc.wait)
        done.set()
        _, slow, churned = await asyncio.gather(*tasks)
        return seen, slow, churned

    seen, slow, churned = asyncio.run(clients())
    return {"seen": seen, "slow": slow, "churned": churned, "evaluation": launch.finish(),
            "bag": bag, "lines": launch.lines}


@pytest.fixture(scope="module")
def ros_domain_module() -> Iterator[int]:
    """A random ROS_DOMAIN_ID for the module's launches (see ``tests.mw_support.ros_domain``)."""
    with pytest.MonkeyPatch.context() as patch:
        yield isolate_domain(patch)


def test_a_foxglove_client_decodes_what_the_recorder_recorded(lockstep_run: dict) -> None:
    """The IMU channel carries the ros2msg schema; decoded with it alone, every message the
    client got equals the bag's message of the same stamp, and none is missing in between."""
    seen: Capture = lockstep_run["seen"]
    assert seen.subprotocol == "foxglove.sdk.v1"
    channel = seen.channels[IMU]
    assert (channel["schemaName"], channel["schemaEncoding"], channel["encoding"]) == (
        "sensor_msgs/msg/Imu", "ros2msg", "cdr")
    recorded = {messages.stamp_ns(m.msg.header.stamp): m.msg
                for m in read_bag(lockstep_run["bag"], messages.TYPESTORE, topics=[IMU],
                                  decode=True)}
    got = seen.messages.get(IMU, [])
    assert len(got) >= 50, f"{len(got)} of {len(recorded)} messages reached the client"
    stamps = [messages.stamp_ns(m.header.stamp) for m in got]
    assert set(stamps) <= set(recorded)
    for msg, stamp in zip(got, stamps, strict=True):
        mine = recorded[stamp]
        assert msg.linear_acceleration.x == mine.linear_acceleration.x
        assert list(msg.linear_acceleration_covariance) == list(
            mine.linear_acceleration_covariance)
    # consecutive samples at 32 Hz: the slow client made the server drop nothing for this one
    period = round(1e9 / 32)
    assert all(abs(b - a - period) <= 1 for a, b in itertools.pairwise(stamps))


def test_clock_drives_the_server_time(lockstep_run: dict) -> None:
    """With sim time the server has the ``time`` capability and broadcasts /clock's times."""
    seen: Capture = lockstep_run["seen"]
    assert "time" in seen.server_info["capabilities"]
    clock = {messages.stamp_ns(m.msg.clock)
             for m in read_bag(lockstep_run["bag"], messages.TYPESTORE, topics=["/clock"],
                               decode=True)}
    assert len(seen.times) >= 50
    assert set(seen.times) <= clock
    assert seen.times == sorted(seen.times)


def test_slow_and_churning_clients_do_not_stop_the_loop(lockstep_run: dict) -> None:
    """A client that never reads and clients that come and go: the launch still ends with
    every sample of the scene (12 s at 32 Hz) and the monitor exits cleanly (exit code 0,
    else the launch would fail naming it)."""
    assert lockstep_run["slow"] >= 5
    assert lockstep_run["churned"] >= 3
    assert lockstep_run["evaluation"]["steps"] == 12 * 32
    assert any("[monitor]" in line and "Forwarded" in line for line in lockstep_run["lines"])
