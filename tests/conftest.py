"""Settings and shared fixtures for the whole suite.

Layout: ``unit/<layer>/`` holds the tests of one layer of the library (docs/architecture.md);
``integration/`` the tests that start DDS participants, node processes or the ``stillframe``
command, all marked ``processes`` here (``pytest -m "not processes"`` runs the numerical core);
``support/`` the helpers they share.

Every DDS participant a test starts (in this process or a child) discovers only this machine:
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, so no discovery traffic leaves the host. Tests of the
other ranges set their own, inside network namespaces of their own. Each test process holds a
ROS_DOMAIN_ID of its own for the whole session (a test that asks for ``ros_domain`` gets another
for itself), so the workers of ``pytest -n`` and a loop running on the default domain never meet.
"""

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ.pop("ROS_LOCALHOST_ONLY", None)
# a graph daemon a test's `stillframe topic|node` call starts leaves a minute after its last use
os.environ["STILLFRAME_DAEMON_IDLE_S"] = "60"


import pytest

from tests.support.middleware import held_domain, isolated_domain

INTEGRATION = Path(__file__).with_name("integration")


@pytest.fixture(scope="session", autouse=True)
def _a_domain_of_the_sessions_own() -> Iterator[int]:
    """The ROS_DOMAIN_ID of the tests that do not ask for one: held by this process for the
    session (the commands a test starts inherit it)."""
    with held_domain() as domain, pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_DOMAIN_ID", str(domain))
        yield domain


@pytest.fixture
def ros_domain(monkeypatch: pytest.MonkeyPatch) -> Iterator[int]:
    """A ROS_DOMAIN_ID (1..200) no other test run on this machine holds, so parallel test runs
    never see each other; discovery on this machine only (no multicast leaves it)."""
    with isolated_domain(monkeypatch) as domain:
        yield domain


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every test under integration/ starts processes or DDS participants."""
    for item in items:
        if INTEGRATION in Path(str(item.fspath)).parents:
            item.add_marker(pytest.mark.processes)


@pytest.fixture(autouse=True)
def _the_suite_keeps_its_priority() -> object:
    """A test that lowers the suite's own CPU priority (a command's ``--nice``/``--idle`` run
    in-process) would slow every later test beside a busy machine: each test must leave the
    process's (niceness, policy) as it found them. The error names the test; the priority is
    put back so that the tests after it run as before."""
    before = os.getpriority(os.PRIO_PROCESS, 0), os.sched_getscheduler(0)
    yield
    after = os.getpriority(os.PRIO_PROCESS, 0), os.sched_getscheduler(0)
    if after != before:
        for task in os.listdir("/proc/self/task"):
            with contextlib.suppress(OSError):
                os.sched_setscheduler(int(task), before[1], os.sched_param(0))
                os.setpriority(os.PRIO_PROCESS, int(task), before[0])
    assert after == before, f"the test changed the suite's (niceness, policy) {before} to {after}"
