"""The degraded verdict of a run (:mod:`stillframe.app.run_verdict`): each reason forced by its
counter in a hand-made evaluation and status, none for a clean run; in lock-step and in one
process only the reasons of every mode (refused commands, a law that ran away)."""

from __future__ import annotations

import pytest

from stillframe.app.run_verdict import (
    DEADLINE_MISS_LIMIT,
    foreign_warning,
    foreign_writers,
    verdict,
)

#: a clean real-time run of 960 samples (30 s at 32 Hz)
CLEAN = {"mode": "realtime", "steps": 960, "deadline_misses": 0, "rejected_commands": 0,
         "commands_in_time": 958, "degraded_samples": 0, "safe_state_samples": 0,
         "reduction_pct": {"displacement": [70.0, 80.0, 63.0]}}
STATUS = {"/frame/controller_node": {"watchdog": "0"}, "/frame/sim_node": {"step": "960"}}


def test_a_clean_run_is_not_degraded() -> None:
    assert verdict(CLEAN, STATUS) == []
    # at the limit, not over it
    at_limit = round(DEADLINE_MISS_LIMIT * 960)
    assert verdict({**CLEAN, "deadline_misses": at_limit - 1}, STATUS) == []


@pytest.mark.parametrize(("changed", "status", "reason"), [
    ({"deadline_misses": 81}, STATUS,
     "81 deadline misses (8.4 % of 960 samples, over 1 %)"),
    ({}, {**STATUS, "/frame/controller_node": {"watchdog": "12"}}, "12 watchdog zeros"),
    ({"rejected_commands": 960}, STATUS, "960 refused commands"),
    ({"commands_in_time": 0}, STATUS, "the controller never commanded in time"),
    ({"degraded_samples": 400, "safe_state_samples": 100}, STATUS,
     "500 of 960 samples degraded (zero actuation applied)"),
])
def test_each_reason_alone(changed: dict, status: dict, reason: str) -> None:
    assert verdict({**CLEAN, **changed}, status) == [reason]


def test_lockstep_and_one_process_runs_give_the_reasons_of_every_mode() -> None:
    """Refused commands and a law that ran away, from controller_node's status or the
    one-process loop's controller counters; the real-time reasons are not theirs."""
    lockstep = {**CLEAN, "mode": "lockstep", "deadline_misses": 81, "commands_in_time": 0}
    assert verdict(lockstep, STATUS) == []
    assert verdict({**lockstep, "rejected_commands": 5},
                   {"/frame/controller_node": {"watchdog": "12", "runaway": "192"}}) == [
        "5 refused commands", "192 commands of the law beyond 10 times their bound, clipped to it"]
    one_process = {"steps": 384, "controller": {"runaway": 192, "watchdog": 0}}
    assert verdict(one_process, {}) == [
        "192 commands of the law beyond 10 times their bound, clipped to it"]


def test_the_issues_run_gives_every_reason_it_had() -> None:
    """81 deadline misses, 12 watchdog zeros and every command refused by an idle peer."""
    run = {**CLEAN, "deadline_misses": 81, "rejected_commands": 960, "commands_in_time": 0}
    assert len(verdict(run, {"/frame/controller_node": {"watchdog": "12"}})) == 4


#: a real-time run beside a foreign writer: 40 of its commands refused by the simulator for
#: lacking the run's token, 3 of the controller's for their stamps
GATE = {"writer": "/frame/controller_node", "ignored_writers": "/rogue_tuner",
        "rejected_foreign_writer": 40, "rejected_second_writer": 0,
        "rejected_unknown_writer": 0, "rejected_ambiguous_writer": 0, "rejected_past_stamp": 3}
BESIDE = {**CLEAN, "rejected_commands": 43, "command_gates": {"pendulum/torque_cmd": GATE}}


def test_a_foreign_writers_refused_commands_are_not_the_controllers() -> None:
    assert verdict(BESIDE, STATUS) == ["3 refused commands"]


def test_foreign_writers_are_named_per_node_and_topic() -> None:
    """The simulator's from its result, the others' from their last status (keys prefixed by the
    topic as the nodes write them); a node that refused nothing is not listed."""
    statuses = {**STATUS, "/frame/estimator_node": {
        "pendulum_torque_cmd_ignored_writers": "/rogue_tuner",
        "pendulum_torque_cmd_rejected_foreign_writer": "12",
        "floor1_imu_ignored_writers": "", "floor1_imu_rejected_foreign_writer": "0"},
        "/frame/sim_node": {"pendulum_torque_cmd_ignored_writers": "stale",
                            "pendulum_torque_cmd_rejected_foreign_writer": "1"}}
    found = foreign_writers(BESIDE, statuses)
    assert found == [
        {"node": "/frame/sim_node", "topic": "/frame/pendulum/torque_cmd",
         "writers": ["/rogue_tuner"], "refused": 40},
        {"node": "/frame/estimator_node", "topic": "/frame/pendulum/torque_cmd",
         "writers": ["/rogue_tuner"], "refused": 12}]
    assert foreign_warning(found) == (
        "samples of writers not of this run refused (the figures are the loop's own nodes'): "
        "/rogue_tuner on /frame/pendulum/torque_cmd (40 refused by /frame/sim_node); "
        "/rogue_tuner on /frame/pendulum/torque_cmd (12 refused by /frame/estimator_node)")
    assert foreign_writers(CLEAN, STATUS) == []


@pytest.mark.parametrize(("practices", "says"), [
    ({"applied": ["gc frozen and off in the loop"],
      "refused": ["SCHED_FIFO not permitted: RLIMIT_RTPRIO 0 and no CAP_SYS_NICE"]},
     "the nodes without SCHED_FIFO (SCHED_FIFO not permitted: RLIMIT_RTPRIO 0 and no "
     "CAP_SYS_NICE): the fix is the real-time practice, add yourself to a `realtime` group "
     "with `@realtime - rtprio 98`"),
    ({"applied": ["gc frozen and off in the loop"], "refused": []},
     "the nodes without SCHED_FIFO (SCHED_FIFO not asked for (--rt)): the fix is the real-time "
     "practice"),
])
def test_deadline_misses_without_sched_fifo_name_the_practice_as_the_fix(
        practices: dict, says: str) -> None:
    reasons = verdict({**CLEAN, "deadline_misses": 81, "realtime": practices}, STATUS)
    assert len(reasons) == 1
    assert reasons[0].startswith("81 deadline misses (8.4 % of 960 samples, over 1 %), " + says)


def test_deadline_misses_with_sched_fifo_say_nothing_of_the_practice() -> None:
    practices = {"applied": ["SCHED_FIFO 80 on 4 threads (CAP_SYS_NICE); BLAS on one thread"],
                 "refused": []}
    assert verdict({**CLEAN, "deadline_misses": 81, "realtime": practices}, STATUS) == [
        "81 deadline misses (8.4 % of 960 samples, over 1 %)"]
    # a run without misses is clean, with or without the practice
    assert verdict({**CLEAN, "realtime": {"applied": [], "refused": []}}, STATUS) == []
