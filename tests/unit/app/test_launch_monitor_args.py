"""``launch --monitor`` starts ``stillframe monitor`` at SCHED_IDLE unless told otherwise."""

from __future__ import annotations

import pytest

from stillframe.app.cli import build_parser
from stillframe.app.launch_cli import monitor_args


@pytest.mark.parametrize(("extra", "expected"), [
    ([], ["--port", "8765", "--dashboard-port", "8080", "--idle"]),
    (["--no-monitor-idle", "--monitor-max-rate", "0"],
     ["--port", "8765", "--dashboard-port", "8080", "--max-rate", "0"]),
])
def test_monitor_arguments(extra: list[str], expected: list[str]) -> None:
    args = build_parser().parse_args(["launch", "scenes/thesis_lqg.yaml", "--monitor", *extra])
    assert monitor_args(args) == expected
