"""``stillframe bench writers``' summary: the misses beside the writer against the twins', per
backend, on hand-made rows."""

from __future__ import annotations

from stillframe.app.bench.writers import summary


def row(backend: str, writer: bool, misses: int) -> dict:
    return {"backend": backend, "writer": writer, "deadline_misses": misses}


def test_the_misses_are_summed_over_the_repeats_and_set_against_the_twins() -> None:
    rows = [row("rclpy", False, 10), row("rclpy", True, 14), row("rclpy", True, 9),
            row("rclpy", False, 2), row("dds", False, 0), row("dds", True, 2),
            row("dds", True, 1), row("dds", False, 0)]
    assert summary(rows) == [
        {"backend": "rclpy", "misses_beside": 23, "misses_alone": 12, "ratio": 23 / 12,
         "within_goal": True},
        # twins without a miss: up to two beside the writer are within the goal, three are not
        {"backend": "dds", "misses_beside": 3, "misses_alone": 0, "ratio": None,
         "within_goal": False}]
    assert summary([row("dds", True, 25), row("dds", False, 12)])[0]["within_goal"] is False
