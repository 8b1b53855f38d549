"""Issue 32 item 4: a recorded real-time run above ``RECORDED_ABOVE_HZ`` puts every child
``--backend`` does not name on ``dds`` when the process's default is ``rclpy``, runs the loop
nodes with the real-time practices and the recorder at SCHED_IDLE; the user's ``--backend`` for
all (or ``STILLFRAME_RMW``), ``--rt`` and ``--recorder-nice`` / ``--recorder-idle`` keep their
choice; lock-step, unrecorded and slow runs keep the defaults (no practices, the recorder as
``ros2 bag record`` runs it)."""

from __future__ import annotations

import argparse

import pytest

from stillframe.app import launcher
from stillframe.app.launch_cli import add_realtime_arguments, realtime_arguments
from stillframe.app.launcher import (
    BACKEND_TARGETS,
    RECORDED_ABOVE_HZ,
    parse_backends,
    practices_default,
    recorded_default,
    recorder_priority,
)
from stillframe.middleware import api
from stillframe.node_runtime.realtime import PRACTICES, parse_practices

FAST = RECORDED_ABOVE_HZ * 5


@pytest.fixture
def rclpy_default(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(api.BACKEND_ENV, raising=False)
    monkeypatch.setattr(launcher.api, "backend_name", lambda: "rclpy")
    monkeypatch.setattr(launcher.api, "check_backend", lambda backend, what: backend)


@pytest.mark.usefixtures("rclpy_default")
def test_a_recorded_fast_realtime_run_goes_on_dds_except_where_the_user_said() -> None:
    assert recorded_default([], record=True, mode="realtime", rate_hz=FAST) == "dds"
    chosen = parse_backends(["recorder=rclpy"], recorded_default(
        ["recorder=rclpy"], record=True, mode="realtime", rate_hz=FAST))
    assert chosen["recorder"] == "rclpy"
    assert {chosen[n] for n in BACKEND_TARGETS if n != "recorder"} == {"dds"}


@pytest.mark.usefixtures("rclpy_default")
@pytest.mark.parametrize(("specs", "record", "mode", "rate_hz"), [
    (["rclpy"], True, "realtime", FAST),                  # the user chose for every child
    ([], False, "realtime", FAST),                        # not recorded
    ([], True, "lockstep", FAST),                         # not paced by the clock
    ([], True, "realtime", RECORDED_ABOVE_HZ),        # slow enough for rclpy
])
def test_the_default_stays_otherwise(specs: list[str], record: bool, mode: str,
                                     rate_hz: float) -> None:
    assert recorded_default(specs, record=record, mode=mode, rate_hz=rate_hz) is None
    assert set(parse_backends(specs).values()) == {"rclpy"}


def test_stillframe_rmw_keeps_the_users_backend(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(api.BACKEND_ENV, "rclpy")
    monkeypatch.setattr(launcher.api, "backend_name", lambda: "rclpy")
    assert recorded_default([], record=True, mode="realtime", rate_hz=FAST) is None


def test_a_recorded_fast_realtime_run_gets_an_idle_recorder() -> None:
    assert recorder_priority(None, mode="realtime", rate_hz=FAST) == ["--idle"]


@pytest.mark.parametrize(("record", "mode", "rate_hz"), [
    (False, "realtime", FAST),                  # not recorded
    (True, "lockstep", FAST),                   # not paced by the clock
    (True, "realtime", RECORDED_ABOVE_HZ),      # slow enough
])
def test_otherwise_the_recorder_as_ros2_bag_runs_it(record: bool, mode: str,
                                                    rate_hz: float) -> None:
    if record:
        assert recorder_priority(None, mode=mode, rate_hz=rate_hz) == []


def test_every_realtime_run_gets_the_practices_and_lockstep_none() -> None:
    given = parse_practices(practices_default(None, mode="realtime"))
    # every practice but the two that need a choice: CPUs to pin to, and holding every CPU of
    # the machine out of idle (docs/realtime.md, "The PM QoS request")
    assert given == frozenset(PRACTICES) - {"affinity", "cpu_latency"}
    assert practices_default(None, mode="lockstep") == ""


def test_rt_alone_is_the_default_practice_and_all_is_every_one() -> None:
    parser = argparse.ArgumentParser()
    add_realtime_arguments(parser)
    alone = realtime_arguments(parser.parse_args(["--rt"]))[0]
    assert alone is not None
    assert parse_practices(alone) == parse_practices(practices_default(None, mode="realtime"))
    every = realtime_arguments(parser.parse_args(["--rt", "all"]))[0]
    assert every is not None and parse_practices(every) == frozenset(PRACTICES)


def test_the_users_choice_is_kept() -> None:
    assert practices_default("", mode="realtime") == ""  # --rt none
    assert practices_default("fifo", mode="realtime") == "fifo"
    assert recorder_priority(["--nice", "0"], mode="realtime", rate_hz=FAST) == ["--nice", "0"]
