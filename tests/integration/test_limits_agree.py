"""A limit the loop enforces acts the same in one process and through the nodes, and a run it
changed says so in both.

``plant.process_noise_std`` of 1e6 (within its bounds) drives the plant so far that every LQG
command is beyond the command bound of the unlimited torque actuator
(:data:`~stillframe.config.loop_sections.COMMAND_BOUND`): the controller clips each to it in both
loops (it never sends a command the simulator would refuse), so ``closed-loop`` and ``launch``
give the same figures, to the last bit, and the same warning reason (the law ran away)."""

from __future__ import annotations

import json

from stillframe.config.loop_sections import COMMAND_BOUND
from tests.support.middleware import run_stillframe

SETS = ["plant.process_noise_std=[1e6,1e6,1e6,1e6,1e6,1e6,1e6,1e6]", "duration=12",
        "controller.start=6", "evaluation.window=5"]


def test_a_runaway_law_is_clipped_and_warned_alike_in_both_loops(ros_domain: int) -> None:
    args = [f"--set={s}" for s in SETS]
    one = run_stillframe("closed-loop", "thesis_lqg", *args, "--json", timeout=120)
    nodes = run_stillframe("launch", "thesis_lqg", *args, "--json", timeout=300)
    assert one.returncode == 0 and nodes.returncode == 0, (one.stderr[-2000:],
                                                           nodes.stderr[-2000:])
    a, b = json.loads(one.stdout), json.loads(nodes.stdout)
    assert a["reduction_pct"] == b["reduction_pct"]
    assert a["peak_command"] == b["peak_command"] == COMMAND_BOUND
    assert b["rejected_commands"] == 0 and b["complete"] is True
    runaway = a["controller"]["runaway"]
    assert runaway > 0 and a["degraded_reasons"] == b["degraded_reasons"] == [
        f"{runaway} commands of the law beyond 10 times their bound, clipped to it"]
