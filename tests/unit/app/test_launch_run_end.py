"""The launcher's end of a run (:func:`run_ended`): the simulator exits with 0 after writing the
result. Real child processes; the interleaving the watch loop can meet (the simulator ends
between the look for failures and the look for its end) is forced by a process whose first
``poll`` still answers "running" after it has exited."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from stillframe.app.launcher import Child, NodeDiedError, ProcessSet, run_ended


class LateToSeeItExit(subprocess.Popen):
    """A child that has exited, whose first ``poll`` answers None: as if it exited just after."""

    looked = False

    def poll(self) -> int | None:
        if not self.looked:
            self.looked = True
            return None
        return super().poll()


def exited(name: str, code: int, popen: type[subprocess.Popen] = subprocess.Popen) -> Child:
    proc = popen([sys.executable, "-c", f"raise SystemExit({code})"])
    proc.wait()
    return Child(name, proc)


def processes(*children: Child) -> ProcessSet:
    group = ProcessSet(echo=print)
    group.children.extend(children)
    return group


def running(name: str) -> Child:
    return Child(name, subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"]))


@pytest.fixture
def result(tmp_path: Path) -> Path:
    path = tmp_path / "result.json"
    path.write_text("{}")
    return path


def test_a_simulator_that_ends_between_the_two_looks_ends_the_run(result: Path) -> None:
    controller = running("controller_node")
    sim = exited("sim_node", 0, LateToSeeItExit)
    try:
        assert run_ended(processes(controller, sim), sim, result)
        assert sim.stop_requested
    finally:
        controller.proc.kill()
        controller.proc.wait()


def test_a_simulator_that_exits_with_0_without_its_result_died(tmp_path: Path) -> None:
    sim = exited("sim_node", 0)
    with pytest.raises(NodeDiedError, match="exit code 0 before the end of the run"):
        run_ended(processes(sim), sim, tmp_path / "result.json")


def test_another_child_that_died_is_named_although_the_simulator_ended(result: Path) -> None:
    estimator, sim = exited("estimator_node", 4), exited("sim_node", 0)
    with pytest.raises(NodeDiedError, match="estimator_node died"):
        run_ended(processes(estimator, sim), sim, result)


def test_a_running_simulator_has_not_ended(result: Path) -> None:
    sim = running("sim_node")
    try:
        assert not run_ended(processes(sim), sim, result)
        assert not sim.stop_requested
    finally:
        sim.proc.kill()
        sim.proc.wait()
