"""``bench loop --track``'s figures: each run with the modal tracker is set against the run
without it at the same backend and rate (not against a recorded run), the figures kept in
pairs, the p99 ratio taken as with / without."""

from __future__ import annotations

from typing import Any

import pytest

from stillframe.app.bench.loop import tracker_rows, tracker_table


def row(backend: str, rate: float, *, misses: int, p50: float, p99: float,
        record: bool = False, track: bool = False, updates: int = 0) -> dict[str, Any]:
    return {"backend": backend, "rate_hz": rate, "record": record, "track": track,
            "deadline_misses": misses, "sim_deadline_misses": None if track else 0,
            "p50_us": p50, "p99_us": p99, "tracker_updates": updates}


def test_each_tracked_run_is_set_against_the_plain_run_of_its_backend_and_rate() -> None:
    rows = [row("dds", 1000.0, misses=3, p50=120.0, p99=400.0),
            row("dds", 1000.0, misses=90, p50=900.0, p99=5000.0, record=True),
            row("dds", 1000.0, misses=5, p50=130.0, p99=500.0, track=True, updates=2),
            row("dds", 100.0, misses=0, p50=200.0, p99=300.0),
            row("dds", 100.0, misses=1, p50=210.0, p99=240.0, track=True, updates=1),
            row("rclpy", 100.0, misses=7, p50=1.0, p99=2.0, track=True)]  # no plain run
    pairs = tracker_rows(rows)
    assert [(p["backend"], p["rate_hz"]) for p in pairs] == [("dds", 1000.0), ("dds", 100.0)]
    first, second = pairs
    assert first["deadline_misses"] == (3, 5)     # the plain run's, not the recorded run's
    assert first["sim_deadline_misses"] == (0, None)
    assert first["p50_us"] == (120.0, 130.0) and first["p99_us"] == (400.0, 500.0)
    assert first["p99_ratio"] == pytest.approx(1.25)
    assert second["p99_ratio"] == pytest.approx(0.8)
    assert (first["tracker_updates"], second["tracker_updates"]) == (2, 1)
    table = tracker_table(pairs).splitlines()
    assert "3 / 5" in table[2] and "400 / 500" in table[2] and "1.25" in table[2]
    assert "0 / -" in table[2]
