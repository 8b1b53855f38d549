"""``stillframe monitor`` during real launches: a real ``foxglove.websocket.v1`` client against
the recorder's bag, slow and churning clients, and the dashboard in headless Chromium."""

from __future__ import annotations

import asyncio
import io
import itertools
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pytest

from stillframe.app.bench.loop import realtime_overrides
from stillframe.bags.storage import read_bag
from stillframe.config.scene import load_scene
from stillframe.contract import messages
from stillframe.identification.tracker import MODES_TOPIC, TrackedModes, modes_array
from stillframe.locations import REPO_ROOT
from stillframe.middleware import api
from stillframe.middleware.names import is_hidden
from stillframe.middleware.taps import TappedPublisher, tap_topic
from stillframe.monitor.dashboard import ERROR_KEYS
from stillframe.monitor.foxglove_client import Capture, capture, churn, stall
from tests.support.middleware import child_env, isolated_domain, niced, scheduling
from tests.support.waits import HANG_S

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
        assert launch.ready.wait(HANG_S), "".join(launch.lines[-30:])
        return launch

    def _read(self) -> None:
        for line in self.proc.stderr:
            self.lines.append(line)
            if (found := READY.search(line.rstrip())) is not None:
                self.urls = (found[1], found[2])
                self.ready.set()
        self.ready.set()

    def finish(self, timeout: float = HANG_S) -> dict:
        """The launch's JSON once it exited (stderr stays the reader thread's: communicate()
        would close it under the thread)."""
        self.proc.wait(timeout=timeout)     # its JSON is far less than a pipe holds
        out = self.proc.stdout.read()
        assert self.proc.returncode == 0, "".join(self.lines[-30:])
        return json.loads(out)


@pytest.fixture(scope="module")
def monitored_run(tmp_path_factory: pytest.TempPathFactory, ros_domain_module: int) -> dict:
    """One launch with the monitor and a recorder of the IMU topic and ``/clock``; meanwhile a
    subscribing client, a client that stops reading, and clients that come and go. Real time,
    so that the 12 s run lasts 12 s whatever the machine's speed (in lock-step it can end before
    a client has subscribed)."""
    bag = tmp_path_factory.mktemp("monitor") / "bag"
    launch = Launch.start(*SHORT, "--mode", "realtime", "--json", "--record", str(bag),
                          "--record-topic", IMU, "--record-topic", "/clock",
                          "--monitor-max-rate", "0", "--no-monitor-idle")
    url = launch.urls[0]

    async def clients() -> tuple[Capture, int, int]:
        done = asyncio.Event()
        seen = Capture()
        tasks = [asyncio.create_task(capture(url, [IMU], done, seen)),
                 asyncio.create_task(stall(url, IMU, done, at_least=5)),
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
    """A ROS_DOMAIN_ID held for the module's launches (as the ``ros_domain`` fixture)."""
    with pytest.MonkeyPatch.context() as patch, isolated_domain(patch) as domain:
        yield domain


def test_a_foxglove_client_decodes_what_the_recorder_recorded(monitored_run: dict) -> None:
    """The IMU channel carries the ros2msg schema; decoded with it alone, every message the
    client got equals the bag's message of the same stamp, and (every sample forwarded: launch
    ``--monitor-max-rate 0``) none is missing in between."""
    seen: Capture = monitored_run["seen"]
    assert seen.subprotocol == "foxglove.sdk.v1"
    channel = seen.channels[IMU]
    assert (channel["schemaName"], channel["schemaEncoding"], channel["encoding"]) == (
        "sensor_msgs/msg/Imu", "ros2msg", "cdr")
    recorded = {messages.stamp_ns(m.msg.header.stamp): m.msg
                for m in read_bag(monitored_run["bag"], messages.TYPESTORE, topics=[IMU],
                                  decode=True)}
    got = seen.messages.get(IMU, [])
    forwarded = [line for line in monitored_run["lines"] if "Forwarded" in line]
    assert len(got) >= 50, f"{len(got)} of {len(recorded)} messages reached the client; {forwarded}"
    stamps = [messages.stamp_ns(m.header.stamp) for m in got]
    assert set(stamps) <= set(recorded)
    for msg, stamp in zip(got, stamps, strict=True):
        mine = recorded[stamp]
        assert msg.linear_acceleration.x == mine.linear_acceleration.x
        assert list(msg.linear_acceleration_covariance) == list(
            mine.linear_acceleration_covariance)
    # every sample (--monitor-max-rate 0), consecutive at 32 Hz: the slow client made the
    # server drop nothing for this one
    period = round(1e9 / 32)
    assert all(abs(b - a - period) <= 1 for a, b in itertools.pairwise(stamps))


def test_clock_drives_the_server_time(monitored_run: dict) -> None:
    """With sim time the server has the ``time`` capability and broadcasts /clock's times."""
    seen: Capture = monitored_run["seen"]
    assert "time" in seen.server_info["capabilities"]
    clock = {messages.stamp_ns(m.msg.clock)
             for m in read_bag(monitored_run["bag"], messages.TYPESTORE, topics=["/clock"],
                               decode=True)}
    # every broadcast time is a sample time of the scene's 32 Hz grid (what /clock carries);
    # the recorder takes /clock best-effort, so the bag need not hold every one of them
    assert len(seen.times) >= 10
    assert all(t % 31_250_000 == 0 and 0 <= t <= 12 * 10**9 for t in seen.times)
    assert len(set(seen.times) & clock) >= 0.9 * len(set(seen.times))
    assert seen.times == sorted(seen.times)


def test_slow_and_churning_clients_do_not_stop_the_loop(monitored_run: dict) -> None:
    """A client that never reads and clients that come and go: the launch still ends with
    every sample of the scene (12 s at 32 Hz) and the monitor exits cleanly (exit code 0,
    else the launch would fail naming it)."""
    assert monitored_run["slow"] >= 5
    assert monitored_run["churned"] >= 3
    assert monitored_run["evaluation"]["steps"] == 12 * 32
    assert any("[monitor]" in line and "Forwarded" in line for line in monitored_run["lines"])


CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--window-size=1500,900")
#: plotly's first trace colour (#1f77b4): the true displacements and angle
TRACE_RGB = np.array([0x1F, 0x77, 0xB4])


def browser(profile: Path) -> Any:
    """Debian's headless Chromium through its chromedriver, browser console logged."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={profile}"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(options=options, service=Service(str(CHROMEDRIVER)))


def trace_pixels(png: bytes) -> int:
    """Pixels of the first trace colour in a screenshot."""
    image = (plt.imread(io.BytesIO(png))[..., :3] * 255).round()
    return int((np.abs(image - TRACE_RGB).max(axis=-1) <= 8).sum())


def plotted_ends(driver: Any) -> list[float]:
    """The last time plotted by each chart's first trace (None while it is empty)."""
    return driver.execute_script(
        "return ['floor1', 'floor2', 'floor3', 'pendulum', 'command'].map(id => {"
        "  const d = document.getElementById(id).data;"
        "  return d && d[0].x.length ? d[0].x[d[0].x.length - 1] : null; });")


@pytest.mark.skipif(not (CHROMIUM.exists() and CHROMEDRIVER.exists()),
                    reason="needs Debian's chromium and chromium-driver "
                           "(apt-get install -y chromium chromium-driver)")
def test_dashboard_in_headless_chromium(tmp_path: Path, ros_domain_module: int) -> None:
    """The dashboard during a real-time launch at 1 kHz: every chart has data, the first trace
    colour is on the page, two screenshots at least 1 s apart differ in the plotted data,
    exactly the non-zero error counters are red (saturation is forced), and the browser logs no
    error. The loop's nodes run without the real-time practices (``--rt none``): under
    SCHED_FIFO a loop that cannot keep up at 1 kHz (a slow or loaded machine) leaves the monitor
    and the browser the kernel's 5 % of the CPU, and the page freezes (docs/monitor.md). The run
    (twice :data:`HANG_S`) outlasts every wait of the test and is ended by SIGINT once the checks
    are done, so the page is checked while the loop runs however late the monitor gets its share
    of the CPU."""
    overrides = [*realtime_overrides(1000.0, 2 * HANG_S), "controller.limit=0.5",
                 "controller.start=1.5", "evaluation.window=1"]
    launch = Launch.start("--mode", "realtime", "--no-monitor-idle", "--rt", "none",
                          *(a for o in overrides for a in ("--set", o)))
    driver = browser(tmp_path / "profile")
    try:
        driver.get(launch.urls[1])
        deadline = time.monotonic() + HANG_S
        # until every chart has data and the controller has been saturating for a while
        while not all(t is not None and t > 2 for t in plotted_ends(driver)):
            assert time.monotonic() < deadline, plotted_ends(driver)
            time.sleep(0.2)
        first, first_ends = driver.get_screenshot_as_png(), plotted_ends(driver)
        time.sleep(1.0)
        deadline = time.monotonic() + HANG_S
        # a second apart at least, and until every chart has plotted newer data (on a loaded
        # machine the loop, and so the data, can advance slower than the wall clock)
        while not all(b > a for a, b in zip(first_ends, plotted_ends(driver), strict=True)):
            assert time.monotonic() < deadline, (first_ends, plotted_ends(driver))
            time.sleep(0.2)
        second, second_ends = driver.get_screenshot_as_png(), plotted_ends(driver)
        cells = driver.execute_script(
            "return [...document.querySelectorAll('td[data-key]')].map("
            "  td => [td.dataset.key, td.textContent, td.classList.contains('error')]);")
        errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        driver.quit()
        launch.proc.send_signal(signal.SIGINT)
        launch.proc.wait(timeout=HANG_S)   # stderr is the reader thread's
    (tmp_path / "dashboard.png").write_bytes(second)
    assert not errors, errors
    assert trace_pixels(first) > 500 and trace_pixels(second) > 500
    assert first != second
    assert all(b > a for a, b in zip(first_ends, second_ends, strict=True)), (first_ends,
                                                                             second_ends)
    # red exactly where an error counter is non-zero; saturation is forced (0.5 N m from 1.5 s)
    for key, value, red in cells:
        assert red == (key in ERROR_KEYS and value not in ("", "0", "False")), (key, value)
    assert any(key == "saturated" and red for key, _, red in cells), cells


def monitor_readers(probe: Any, topic: str) -> int:
    """Readers of ``topic`` that the DDS graph shows in the monitor's node."""
    return sum(info.node_name == "stillframe_monitor"
               for info in probe.get_subscriptions_info_by_topic(topic))


PUBLISH_HZ = 200


@dataclass
class ImuSource:
    node: Any
    #: published with a monitor tap, as the loop's nodes publish
    tapped: bool


@pytest.fixture(params=[False, True], ids=["plain", "tapped"])
def imu_source(request: pytest.FixtureRequest, ros_domain: int) -> Iterator[ImuSource]:
    """A node publishing the IMU topic at :data:`PUBLISH_HZ`, stamps counting periods; with a
    monitor tap as the loop's nodes publish it, or without (another publisher, a bag played)."""
    source = api.create_node("imu_source")
    publisher = (TappedPublisher(source, "sensor_msgs/msg/Imu", IMU, "sensor_data")
                 if request.param else
                 source.create_publisher("sensor_msgs/msg/Imu", IMU, "sensor_data"))
    stop = threading.Event()

    def publish() -> None:
        msg = messages.new("sensor_msgs/msg/Imu")
        for k in itertools.count():
            if stop.wait(1 / PUBLISH_HZ):
                return
            msg.header.stamp = messages.time_msg(k * 10**9 // PUBLISH_HZ)
            publisher.publish(msg)

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    yield ImuSource(source, request.param)
    stop.set()
    thread.join()
    source.destroy_node()


def start_monitor(*args: str) -> tuple[subprocess.Popen, str, str | None]:
    """``stillframe monitor ARGS`` on a free port; the process, its Foxglove URL and, with
    ``--dashboard``, the dashboard's."""
    monitor = subprocess.Popen([sys.executable, "-m", "stillframe", "monitor", "--port", "0",
                                *args], env=child_env(), cwd=REPO_ROOT,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    line = ""
    while (found := READY.search(line.rstrip())) is None:
        line = monitor.stderr.readline()
        assert line, "the monitor ended before it was ready"
    return monitor, found[1], found[2]


def stop_monitor(monitor: subprocess.Popen) -> str:
    """SIGINT, then its stderr; it must exit 0."""
    monitor.send_signal(signal.SIGINT)
    _, err = monitor.communicate(timeout=HANG_S)
    assert monitor.returncode == 0, err[-2000:]
    return err


#: the least time a client watches, and the samples a watched topic must bring before it leaves
LEAST_S, LEAST_SAMPLES = 3.0, 10


async def watch_until(url: str, topics: list[str],
                      enough: Callable[[Capture], bool]) -> Capture:
    """Connect to ``url``, subscribe to ``topics`` and leave once ``enough(what came)`` holds,
    however late a loaded machine gets there (:data:`HANG_S` ends a hang); what came."""
    seen, until = Capture(), asyncio.Event()
    task = asyncio.create_task(capture(url, topics, until, seen))
    deadline = time.monotonic() + HANG_S
    while not (enough(seen) or task.done() or time.monotonic() > deadline):
        await asyncio.sleep(0.1)
    until.set()
    await task
    return seen


async def watch(url: str, topics: list[str], probe: Any, read: str, *,
                readers: int) -> tuple[Capture, int]:
    """:func:`watch_until` :data:`LEAST_S` have passed, the IMU channel is advertised, at least
    :data:`LEAST_SAMPLES` of each watched topic came and the monitor's readers of ``read`` (the
    IMU topic or its tap) are ``readers``. What came, and the readers just before leaving."""
    began, found = time.monotonic(), [-1]

    def enough(seen: Capture) -> bool:
        found[0] = monitor_readers(probe, read)
        return (time.monotonic() - began >= LEAST_S and IMU in seen.channels
                and all(len(seen.messages.get(t, ())) >= LEAST_SAMPLES for t in topics)
                and found[0] == readers)

    seen = await watch_until(url, topics, enough)
    return seen, found[0]


def test_a_topic_is_subscribed_only_while_a_client_watches_it(imu_source: ImuSource) -> None:
    """Like foxglove_bridge: the monitor advertises a topic once it has a publisher, but has a
    reader on it (as the DDS graph shows) only while a client is subscribed to its channel;
    the reader goes when the client leaves. A topic nobody watches costs its publisher
    nothing. Watched, the topic comes at most at ``--max-rate`` (default 50 Hz) from a
    200 Hz publisher, the newest sample each time. A tapped topic is read from its tap (the
    hidden twin is never advertised): the publisher sends the monitor none of its samples."""
    probe, read = imu_source.node, tap_topic(IMU) if imu_source.tapped else IMU
    monitor, url, _ = start_monitor()
    try:
        looked, idle_readers = asyncio.run(watch(url, [], probe, read, readers=0))
        assert IMU in looked.channels and not any(map(is_hidden, looked.channels))
        began = time.monotonic()
        watched, readers = asyncio.run(watch(url, [IMU], probe, read, readers=1))
        watched_s = time.monotonic() - began    # at least the 3 s: a loaded machine ends late
        assert (idle_readers, readers) == (0, 1)
        assert monitor_readers(probe, IMU if imu_source.tapped else tap_topic(IMU)) == 0
        assert api.spin_until(probe, lambda: monitor_readers(probe, read) == 0, HANG_S)
    finally:
        err = stop_monitor(monitor)
    assert f"Unsubscribed from topic '{read}' (not watched)" in err
    stamps = [messages.stamp_ns(m.header.stamp) for m in watched.messages[IMU]]
    assert stamps == sorted(set(stamps))
    # 50 Hz at most over the time the client was connected (+1 for the phase), of the 200 a
    # second published: one sample a poll (152 in 3.0 s came when a poll took until empty)
    assert LEAST_SAMPLES <= len(stamps) <= 50 * watched_s + 1, (len(stamps), watched_s)


def test_every_sample_with_max_rate_zero(imu_source: ImuSource) -> None:
    """``--max-rate 0``: every sample of the 200 Hz publisher reaches the client, in order,
    none missing between the first and the last: read from the topic, tapped or not (a tap
    carries at most 50 a second). Watched until 300 samples came, however slowly a loaded
    machine publishes and forwards them (:data:`HANG_S` only ends a hang)."""
    monitor, url, _ = start_monitor("--max-rate", "0")
    try:
        watched = asyncio.run(watch_until(
            url, [IMU], lambda seen: len(seen.messages.get(IMU, ())) >= 300))
    finally:
        stop_monitor(monitor)
    periods = [messages.stamp_ns(m.header.stamp) * PUBLISH_HZ // 10**9
               for m in watched.messages.get(IMU, [])]
    assert len(periods) >= 300
    assert periods == list(range(periods[0], periods[0] + len(periods)))


def dashboard_data(page: str) -> dict:
    """The dashboard's ``/data`` answer."""
    with urllib.request.urlopen(page + "data", timeout=HANG_S) as response:
        return json.loads(response.read())


def test_tracked_modes_reach_the_dashboard_and_foxglove(ros_domain: int) -> None:
    """A publisher of ``identification/modes`` (the modal tracker's message, built by its own
    :func:`modes_array`): the dashboard's ``/data`` serves the published modes with their
    intervals, and a foxglove.websocket client decodes the same values from the bridge."""
    tracked = TrackedModes(10.0, np.array([1.6512, 5.0487]), np.array([0.0213, 0.0104]),
                           np.array([[1.6401, 1.6623], [5.0312, 5.0662]]),
                           np.array([[0.0151, 0.0275], [0.0072, 0.0136]]))
    topic = f"/frame/{MODES_TOPIC}"
    source = api.create_node("tracker_stand_in")
    publisher = source.create_publisher("std_msgs/msg/Float64MultiArray", topic, 10)
    msg = messages.new("std_msgs/msg/Float64MultiArray")
    dims, data = modes_array(tracked)
    msg.layout.dim = [messages.new("std_msgs/msg/MultiArrayDimension", label=label, size=size,
                                   stride=stride) for label, size, stride in dims]
    msg.data = np.asarray(data, dtype=float)
    stop = threading.Event()

    def publish() -> None:
        while not stop.wait(0.2):
            publisher.publish(msg)

    threading.Thread(target=publish, daemon=True).start()
    monitor, url, page = start_monitor("--dashboard", "--dashboard-port", "0")

    async def watch_both() -> tuple[Capture, dict]:
        done, seen, board = asyncio.Event(), Capture(), {}
        task = asyncio.create_task(capture(url, [topic], done, seen))
        deadline = time.monotonic() + HANG_S
        while not (board.get("updates") and seen.messages.get(topic)):
            assert time.monotonic() < deadline, (board, seen.channels)
            await asyncio.sleep(0.3)
            board = (await asyncio.to_thread(dashboard_data, page))["tracked_modes"]
        done.set()
        await task
        return seen, board

    try:
        seen, board = asyncio.run(watch_both())
    finally:
        stop.set()
        stop_monitor(monitor)
        source.destroy_node()
    assert board["modes"] == tracked.record()["modes"]
    assert board["modes"][1] == {"frequency_hz": 5.0487, "damping_ratio": 0.0104,
                                 "frequency_ci": [5.0312, 5.0662],
                                 "damping_ci": [0.0072, 0.0136]}
    assert seen.channels[topic]["schemaName"] == "std_msgs/msg/Float64MultiArray"
    got = seen.messages[topic][-1]
    assert [(d.label, d.size, d.stride) for d in got.layout.dim] == dims
    assert got.data.tolist() == data


def test_idle_monitor_runs_at_sched_idle(ros_domain: int) -> None:
    """``--idle`` (what ``launch --monitor`` passes unless ``--no-monitor-idle``): the process
    is SCHED_IDLE once it is ready, so every thread it started inherited the policy (and the
    default niceness, 10)."""
    monitor, _, _ = start_monitor("--idle")
    try:
        threads = os.listdir(f"/proc/{monitor.pid}/task")
        seen = scheduling(monitor.pid)
    finally:
        stop_monitor(monitor)
    assert len(threads) > 1 and seen == {(os.SCHED_IDLE, niced(10))}    # and its default --nice 10


def test_the_help_names_the_subprotocol_the_server_accepts(ros_domain: int) -> None:
    """Every WebSocket subprotocol ``monitor --help`` names, offered alone, is accepted by the
    running server; the old name ``foxglove.websocket.v1``, which it refuses, is not named."""
    import websockets

    shown = subprocess.run([sys.executable, "-m", "stillframe", "monitor", "--help"],
                           env=child_env(), cwd=REPO_ROOT, capture_output=True, text=True,
                           timeout=60).stdout
    named = sorted(set(re.findall(r"foxglove\.[a-z]+\.v\d", shown)))
    assert named == ["foxglove.sdk.v1"], shown

    async def accepted(url: str, subprotocol: str) -> bool:
        try:
            async with websockets.connect(url, subprotocols=[subprotocol]) as ws:
                return ws.subprotocol == subprotocol
        except websockets.InvalidStatus:
            return False

    monitor, url, _ = start_monitor()
    try:
        assert all(asyncio.run(accepted(url, name)) for name in named)
        assert not asyncio.run(accepted(url, "foxglove.websocket.v1"))   # why it is not named
    finally:
        stop_monitor(monitor)


def test_the_scene_is_a_file_or_a_shipped_scenes_name(ros_domain: int) -> None:
    """``--scene thesis_lqg`` as ``launch`` takes it: the dashboard marks its controller's start
    (25 s; without a scene, none)."""
    monitor, _, page = start_monitor("--dashboard", "--dashboard-port", "0", "--scene",
                                     "thesis_lqg")
    try:
        shown = dashboard_data(page)
    finally:
        stop_monitor(monitor)
    assert shown["controller_start"] == load_scene(SCENE).controller.start == 25.0


@pytest.mark.parametrize(("args", "message"), [
    (["monitor", "--port", "70000"], "--port 70000: expected 0..65535"),
    (["monitor", "--dashboard", "--scene", "no/such.yaml"], "no/such.yaml"),
    (["bench", "monitor", "--repeats", "0"], "--repeats must be >= 1"),
])
def test_bad_monitor_arguments_are_one_line(args: list[str], message: str) -> None:
    done = subprocess.run([sys.executable, "-m", "stillframe", *args], env=child_env(),
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
