"""``stillframe bench loop``'s bookkeeping (no wall-clock asserts): the latency log against
numbers worked out by hand and numpy's percentiles, the scene overrides it runs, bad input."""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

from stillframe.app.bench.busy import busy_loops
from stillframe.app.bench.latency import LatencyLog
from stillframe.app.bench.loop import (
    goal_rows,
    loaded_table,
    realtime_overrides,
    stamp_ns,
    watchdog_zeros,
    within_period_pct,
)
from stillframe.config.scene import load_scene
from stillframe.contract import messages
from stillframe.locations import REPO_ROOT
from tests.support.middleware import run_stillframe

MS = 1_000_000


def test_latency_pairs_commands_with_their_samples_by_stamp() -> None:
    log = LatencyLog(period_ns=10 * MS)  # 100 Hz
    # samples k = 0..5 received at 10 k ms + 0.1 ms; commands for k = 0..3 after 2, 4, 12, 3 ms
    for k in range(6):
        log.on_sample(k * 10 * MS, k * 10 * MS + 100_000)
    for k, delay_ms in enumerate([2, 4, 12, 3]):
        log.on_command(k * 10 * MS, k * 10 * MS + 100_000 + delay_ms * MS)
    log.on_command(0, 10**12)               # a second command for stamp 0: the first counts
    log.on_sample(0, 5)                     # a repeated sample: the first receipt counts
    s = log.summary()
    expected = np.array([2.0, 4.0, 12.0, 3.0]) * 1e3
    assert s["samples"] == 6 and s["answered"] == 4
    assert s["p50_us"] == pytest.approx(3500.0)
    assert s["p99_us"] == pytest.approx(np.percentile(expected, 99))
    assert s["max_us"] == pytest.approx(12000.0)
    assert s["deadline_misses"] == 1         # 12 ms > one 10 ms period
    assert s["unanswered"] == 0              # k = 4, 5 came after the last command: in flight


def test_unanswered_samples_before_the_last_command_are_counted() -> None:
    log = LatencyLog(period_ns=MS)
    for k in range(4):
        log.on_sample(k * MS, k * MS)
    log.on_command(0, 100)
    log.on_command(3 * MS, 3 * MS + 100)
    s = log.summary()
    assert (s["answered"], s["unanswered"], s["deadline_misses"]) == (2, 2, 0)


def test_samples_before_the_first_command_are_unobserved_not_unanswered() -> None:
    """Until the observer's command reader is matched with the controller's writer (on Fast
    DDS up to 1.5 s into a run), no command can reach it: samples 0 and 1 are unobserved; the
    missing command of sample 4, between the first and the last command seen, is unanswered."""
    log = LatencyLog(period_ns=MS)
    for k in range(7):
        log.on_sample(k * MS, k * MS)
    for k in (2, 3, 5):
        log.on_command(k * MS, k * MS + 100)
    s = log.summary()
    assert (s["unobserved"], s["answered"], s["unanswered"]) == (2, 3, 1)


def test_the_watchdog_s_zeros_are_not_answers_within_the_period() -> None:
    """1000 samples seen, 990 answered of which 4 late, 10 unanswered; the controller's last
    status counts 6 watchdog zeros: (990 - 4 - 6) / 1000 within the period."""
    summary = {"answered": 990, "unanswered": 10, "deadline_misses": 4}
    statuses = {"/frame/estimator_node": {"watchdog": "99"},
                "/frame/controller_node": {"commands": "990", "watchdog": "6"}}
    zeros = watchdog_zeros(statuses)
    assert zeros == 6 and within_period_pct(summary, zeros) == pytest.approx(98.0)
    assert watchdog_zeros({"/frame/sim_node": {"step": "3"}}) is None
    assert math.isnan(within_period_pct({"answered": 0, "unanswered": 0,
                                         "deadline_misses": 0}, 0))


def test_empty_log_reports_nan_not_an_error() -> None:
    s = LatencyLog(period_ns=MS).summary()
    assert s["answered"] == 0 and math.isnan(s["p50_us"])


@pytest.mark.parametrize(("rate", "steps_per_sample"), [(100.0, 10), (1000.0, 1)])
def test_realtime_overrides_make_a_valid_scene(rate: float, steps_per_sample: int) -> None:
    scene = load_scene(REPO_ROOT / "scenes" / "thesis_lqg.yaml", realtime_overrides(rate, 6.0))
    assert scene.sensors.rate_hz == rate
    assert scene.integrator.dt * steps_per_sample == pytest.approx(1.0 / rate, rel=1e-12)
    assert scene.duration == 6.0 and scene.controller.start == 3.0


def test_bench_loop_rejects_a_short_duration() -> None:
    done = run_stillframe("bench", "loop", "--duration", "0.5")
    assert done.returncode == 2
    assert done.stderr.strip() == "stillframe bench: error: bench loop: --duration must be >= 1 s"


def test_goals_are_judged_per_backend_and_rate() -> None:
    """The goals of issue 10 against figures made up to sit on both sides of each bound."""
    rows = [{"backend": "dds", "rate_hz": 1000.0, "within_period_pct": 99.95, "p99_us": 480.0,
             "max_us": 2500.0},
            {"backend": "dds", "rate_hz": 100.0, "within_period_pct": 100.0, "p99_us": 501.0,
             "max_us": 900.0}]
    speeds = [{"backend": "dds", "nodes_steps_per_s": 2500.0, "one_process_steps_per_s": 1982.0},
              {"backend": "rclpy", "nodes_steps_per_s": 790.0, "one_process_steps_per_s": 1982.0}]
    goals = {(g["figure"], g["backend"]): g["met"] for g in goal_rows(rows, speeds)}
    assert goals == {
        ("answered within the period [%], 1000 Hz", "dds"): True,
        ("latency p99 [us], 1000 Hz", "dds"): True,
        ("latency max [us], 1000 Hz", "dds"): False,
        ("latency p99 [us], 100 Hz", "dds"): False,
        ("lock-step through the nodes [steps/s]", "dds"): True,
        ("lock-step through the nodes [steps/s]", "rclpy"): False,
        ("one process [steps/s]", "-"): False,     # once: it involves no backend
    }


def test_observer_reads_the_stamp_from_the_cdr() -> None:
    msg = messages.new("geometry_msgs/msg/WrenchStamped")
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345
    assert stamp_ns(messages.serialize(msg)) == 12_000_000_345


def test_bench_loop_rejects_a_bad_rate_and_rt_practice() -> None:
    done = run_stillframe("bench", "loop", "--rate", "0", "--backend", "dds")
    assert done.returncode == 2 and "--rate must be 1..10000 Hz" in done.stderr
    done = run_stillframe("bench", "loop", "--rt", "turbo", "--backend", "dds")
    assert done.returncode == 2 and "unknown practice(s) turbo" in done.stderr
    done = run_stillframe("bench", "loop", "--repeat", "0", "--backend", "dds")
    assert done.returncode == 2 and "--repeat must be 1..100, got 0" in done.stderr


def test_busy_loops_run_while_the_block_runs_and_not_after() -> None:
    """Each loop spins in its own session (its own process group) and uses CPU; none is left."""
    with busy_loops(2) as pids:
        assert len(pids) == 2 and all(os.getpgid(pid) == pid for pid in pids)
        ticks = [_cpu_ticks(pid) for pid in pids]
        # each loop gets CPU time: waited for (a loaded machine may take a while to run them),
        # bounded against a loop that never runs
        deadline = time.monotonic() + 60.0
        while not all(_cpu_ticks(pid) > t for pid, t in zip(pids, ticks, strict=True)):
            assert time.monotonic() < deadline, "a busy loop used no CPU time in 60 s"
            time.sleep(0.05)
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def _cpu_ticks(pid: int) -> int:
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])        # utime + stime


def test_a_loaded_run_is_set_against_its_quiet_twin() -> None:
    quiet = {"backend": "dds", "rate_hz": 1000.0, "rt": "all", "repeat": 0, "record": False,
             "track": False, "busy_loops": 0, "within_period_pct": 99.95, "p50_us": 300.0,
             "p99_us": 450.0, "max_us": 900.0, "sim_deadline_misses": 5}
    loaded = {**quiet, "busy_loops": 2, "within_period_pct": 99.5, "p99_us": 900.0,
              "sim_deadline_misses": 50}
    table = loaded_table([quiet, loaded])
    row = table.splitlines()[-1]
    for cell in ("99.95 / 99.50", "450 / 900", "5 / 50", "2.00"):
        assert cell in row
    assert len(table.splitlines()) == 3          # the quiet run has no row of its own
