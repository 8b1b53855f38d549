"""``bench loop --record``'s verdict: each recorded run is set against the unrecorded run of the
same backend, rate and repeat, and holds issue 32's bound only with at most twice its deadline
misses, no degraded sample, and a complete bag without holes."""

from __future__ import annotations

import math
from typing import Any

import pytest

from stillframe.app.bench.loop import recorder_table, recorder_verdict, twin


def row(backend: str = "rclpy", *, misses: int, record: bool = False, repeat: int = 0,
        degraded: int = 0, complete: bool = True, holes: int = 0) -> dict[str, Any]:
    r = {"backend": backend, "rate_hz": 1000.0, "record": record, "track": False,
         "repeat": repeat, "sim_deadline_misses": misses, "degraded_samples": degraded,
         "p50_us": 300.0, "p99_us": 600.0, "steps": 10_000, "nodes_cpu_s": 12.0}
    if record:
        r.update(complete=complete, per_step_holes=holes, per_step_min=10_000 if complete else 9,
                 recorder_cpu_us_per_msg=15.0, recorder_msgs_per_s=11_000.0,
                 write_path_msgs_per_s=9e5, mcap_msgs_per_s=3e5)
    return r


def test_a_recorded_run_is_set_against_its_own_repeat() -> None:
    rows = [row(misses=40, repeat=0), row(misses=80, record=True, repeat=0),
            row(misses=10, repeat=1), row(misses=80, record=True, repeat=1),
            row("dds", misses=1, repeat=1)]
    assert twin(rows, rows[1]) is rows[0] and twin(rows, rows[3]) is rows[2]
    assert recorder_verdict(rows[1], rows[0]) == (pytest.approx(2.0), True)
    assert recorder_verdict(rows[3], rows[2]) == (pytest.approx(8.0), False)
    table = recorder_table(rows).splitlines()
    assert table[3].split()[-2:] == ["2.00", "yes"] and table[5].split()[-2:] == ["8.00", "NO"]


@pytest.mark.parametrize("recorded", [
    row(misses=81, record=True),                    # over twice 40
    row(misses=10, record=True, degraded=1),        # a degraded sample
    row(misses=10, record=True, complete=False),    # a per-step topic short
    row(misses=10, record=True, holes=3),           # samples lost while recording
])
def test_the_bound_fails_on_each_of_its_conditions(recorded: dict[str, Any]) -> None:
    assert recorder_verdict(recorded, row(misses=40))[1] is False


def test_no_twin_and_no_misses_without_the_recorder() -> None:
    ratio, holds = recorder_verdict(row(misses=3, record=True), None)
    assert math.isnan(ratio) and not holds
    assert recorder_verdict(row(misses=0, record=True), row(misses=0)) == (1.0, True)
    assert recorder_verdict(row(misses=2, record=True), row(misses=0)) == (math.inf, True)
    assert recorder_verdict(row(misses=3, record=True), row(misses=0))[1] is False
