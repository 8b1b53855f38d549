"""The machine-stall probe (:mod:`stillframe.app.bench.stall_probe`): cyclictest, stopped for a
known time, reports a stall at least that long on every CPU."""

from __future__ import annotations

import os
import shutil
import signal
import time

import pytest

from stillframe.app.bench.stall_probe import stall_probe, summary
from stillframe.errors import InputError

needs_cyclictest = pytest.mark.skipif(
    shutil.which("cyclictest") is None or os.geteuid() != 0,
    reason="cyclictest (rt-tests) runs at SCHED_FIFO as root; .ci/run installs it")


@needs_cyclictest
def test_a_forced_stall_is_seen_on_every_cpu_at_least_as_long_as_it_was() -> None:
    with stall_probe() as probe:
        time.sleep(0.5)                                 # the threads are running
        os.kill(probe.pid, signal.SIGSTOP)
        stopped = time.monotonic_ns()
        time.sleep(0.2)
        os.kill(probe.pid, signal.SIGCONT)
        held_us = (time.monotonic_ns() - stopped) // 1000
        time.sleep(0.3)
    cpus = probe.summary["probe_cpus"]
    assert sorted(c["cpu"] for c in cpus) == sorted(os.sched_getaffinity(0))
    # cyclictest's wake planned just after the stop is late by the whole stop, less one period.
    # The stop lasts at least the 0.2 s slept between the two signals (``held_us`` measures the
    # same from this side and can only be longer), less one period for each signal's delivery
    # on a loaded machine.
    assert all(c["max_us"] >= 200_000 - 3 * 1000 for c in cpus), (held_us, cpus)
    assert all(c["stalls"] >= 1 for c in cpus)
    assert probe.summary["probe_max_us"] == max(c["max_us"] for c in cpus)


def test_the_summary_counts_the_wakes_beyond_the_histogram() -> None:
    """cyclictest's JSON holds a histogram up to STALL_US; the later wakes are the cycles it
    does not hold."""
    result = {"thread": {
        "0": {"cpu": 0, "cycles": 10, "max": 4200, "histogram": {"20": 7, "35": 1}},
        "1": {"cpu": 1, "cycles": 10, "max": 300, "histogram": {"21": 10}},
    }}
    assert summary(result) == {
        "probe_cpus": [{"cpu": 0, "cycles": 10, "max_us": 4200, "stalls": 2},
                       {"cpu": 1, "cycles": 10, "max_us": 300, "stalls": 0}],
        "probe_max_us": 4200, "probe_stalls": 2}


def test_without_cyclictest_the_probe_says_what_to_install(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PATH", "/nonexistent")
    with pytest.raises(InputError, match="apt install rt-tests"), stall_probe():
        pass
