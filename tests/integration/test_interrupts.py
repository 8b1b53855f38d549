"""Ctrl-C at any moment (issue 38, item 2; ``stillframe/interrupts.py``): SIGINT to the process
group of each long command, as a terminal sends it, at 20 points of its run drawn with a fixed
seed (its start-up included: the first point is the moment its first line has run), and each
time: one line, exit code 130, no traceback, and no process it started left behind.

Each point is forced, not timed: the command is stopped (SIGSTOP) at the point, the test reads
that it is still alive (``/proc``: stopped, not ended), sends SIGINT and lets it go on
(SIGCONT), so the signal reaches a live process at that point whatever the machine's load; a
point after the command's end is counted as such. "Its first line has run" is read from
``/proc/PID/status``: the entry point's first act installs the SIGTERM handler (before that the
interpreter is still starting, which is Python's, docstring of ``stillframe.interrupts``).
The command runs as the only child of a child subreaper (``tests/support/reaper.py``), which
lists every process it left (running or not reaped) once it has ended.

``record``, ``play`` and ``monitor`` stop on Ctrl-C by design (``ros2 bag record`` and ``play``
do): once their node runs, SIGINT ends them with their summary and exit code 0; before that, as
the others, with the interrupted line and 130.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest

from stillframe.config.environment import MAX_DOMAIN_ID
from stillframe.locations import REPO_ROOT
from tests.support.middleware import child_env

REAPER = REPO_ROOT / "tests" / "support" / "reaper.py"
SEED = 38
POINTS = 20
#: cases run at once (each in its own ROS domain where it uses DDS)
AT_ONCE = 4
#: the domains of the DDS cases: above the 1..200 that the suite's ``ros_domain`` fixture draws
#: from (tests/support/middleware.py), so that no other test's loop shares one (a second loop
#: on a domain is refused by launch), and short of 221, which a unit test names
OWN_DOMAINS = tuple(d for d in range(201, MAX_DOMAIN_ID + 1) if d != 221)
#: the longest a case may take from start to report [s] (a hang fails it)
BOUND_S = 240.0
SHORT = ["--set", "duration=2", "--set", "controller.start=1", "--set", "evaluation.window=1"]
IDENTIFY = ["--input", "/frame/excitation/wrench:wrench.force.x",
            "--output", "/frame/floor1/imu:linear_acceleration.x"]
#: what ends a command that stops on Ctrl-C cleanly (its summary line)
SUMMARY = {"record": "Recorded ", "play": "Published ", "monitor": "Forwarded "}
#: what a command that runs until it is stopped says once it runs
READY = {"record": "Recording to", "monitor": "Monitor ready"}


@dataclass(frozen=True)
class Command:
    name: str
    argv: tuple[str, ...]
    dds: bool = False

    def args(self, where: Path) -> list[str]:
        return [sys.executable, "-m", "stillframe",
                *(a.replace("{tmp}", str(where)) for a in self.argv)]


COMMANDS = (
    Command("simulate", ("simulate", "thesis_lumped", "--duration", "2")),
    Command("identify", ("identify", str(REPO_ROOT / "bags" / "hammer"), *IDENTIFY)),
    Command("closed-loop", ("closed-loop", "thesis_lqg", *SHORT)),
    Command("launch", ("launch", "thesis_lqg", *SHORT, "--out", "{tmp}/out"), dds=True),
    Command("record", ("record", "-a", "-o", "{tmp}/bag"), dds=True),
    Command("play", ("play", str(REPO_ROOT / "bags" / "hammer"), "--rate", "4", "--delay", "0"),
            dds=True),
    Command("monitor", ("monitor", "--port", "0"), dds=True),
)


@dataclass
class Outcome:
    command: str
    point_s: float
    delivered: bool
    code: int
    stdout: str
    stderr: str
    left: list


def _state(pid: int) -> str:
    """The process's state letter (``T`` stopped, ``Z`` ended), ``X`` when it is gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
    except (OSError, IndexError):
        return "X"


def _catches_sigterm(pid: int) -> bool:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return True     # ended: nothing left to wait for
    caught = next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt"))
    return bool(int(caught, 16) & (1 << (signal.SIGTERM - 1)))


def _wait(condition: object, what: str) -> None:
    deadline = time.monotonic() + BOUND_S
    while not condition():          # type: ignore[operator]
        if time.monotonic() > deadline:
            raise AssertionError(f"no {what} within {BOUND_S} s")
        time.sleep(0.005)


def run_case(command: Command, point_s: float | None, where: Path, env: dict[str, str]
             ) -> Outcome:
    """Run ``command`` under the reaper; at ``point_s`` after its first line (None: never, for
    its span) stop it, and if it still runs, send SIGINT to its process group."""
    where.mkdir(parents=True)
    report = where / "report.json"
    out, err = where / "stdout", where / "stderr"
    with out.open("w") as stdout, err.open("w") as stderr:
        reaper = subprocess.Popen(
            [sys.executable, str(REAPER), str(report), *command.args(where)], env=env,
            cwd=REPO_ROOT, stdin=subprocess.DEVNULL, stdout=stdout, stderr=stderr)
    delivered = False
    try:
        pid_file = report.with_suffix(".pid")
        _wait(lambda: pid_file.exists() and pid_file.read_text(), "pid")
        pid = int(pid_file.read_text())
        _wait(lambda: _catches_sigterm(pid), "entry point")
        started = time.monotonic()
        if point_s is None:
            if command.name in READY:       # runs until stopped: once it runs, Ctrl-C
                _wait(lambda: READY[command.name] in err.read_text(), READY[command.name])
                os.killpg(pid, signal.SIGINT)
        else:
            time.sleep(point_s)
            try:
                os.killpg(pid, signal.SIGSTOP)
                _wait(lambda: _state(pid) in "TtZX", "stop")
                if _state(pid) in "Tt":
                    os.killpg(pid, signal.SIGINT)
                    delivered = True
                os.killpg(pid, signal.SIGCONT)
            except ProcessLookupError:
                pass        # ended before the point
        reaper.wait(timeout=BOUND_S)
        ran_s = time.monotonic() - started
    finally:
        if reaper.poll() is None:
            reaper.kill()
            reaper.wait()
    result = json.loads(report.read_text())
    return Outcome(command.name, point_s if point_s is not None else ran_s, delivered,
                   result["code"], out.read_text(), err.read_text(), result["left"])


def check(outcome: Outcome) -> None:
    where = f"{outcome.command} at {outcome.point_s:.2f} s: exit {outcome.code}: " \
            f"{outcome.stderr[-1500:]}"
    assert "Traceback" not in outcome.stderr and "Fatal Python" not in outcome.stderr, where
    assert outcome.left == [], f"{where}\nleft behind: {outcome.left}"
    lines = outcome.stderr.strip().splitlines()
    ours = [line for line in lines
            if line.startswith(f"stillframe {outcome.command}: interrupted")]
    if not outcome.delivered:       # the point came after the end: a whole run
        assert outcome.code == 0, where
        return
    summary = SUMMARY.get(outcome.command)
    if summary and outcome.code == 0:
        assert any(summary in line for line in lines) and not ours, where
        return
    assert outcome.code == 130, where
    assert len(ours) == 1 and lines[-1] == ours[0], where


class Domains:
    """ROS domains for the DDS cases, each case one of its own while it runs, taken in turn
    from :data:`OWN_DOMAINS` (the longest possible rest between two cases of one domain, so
    that nothing a case left in the graph is there for the next)."""

    def __init__(self) -> None:
        self.free: deque[int] = deque(OWN_DOMAINS)
        self.lock = threading.Lock()

    def run(self, command: Command, point_s: float | None, where: Path) -> Outcome:
        if not command.dds:
            return run_case(command, point_s, where, child_env())
        with self.lock:
            domain = self.free.popleft()
        try:
            return run_case(command, point_s, where, {**child_env(), "STILLFRAME_RMW": "dds",
                                                      "ROS_DOMAIN_ID": str(domain)})
        finally:
            with self.lock:
                self.free.append(domain)


@pytest.mark.slow
@pytest.mark.long      # 147 runs of 7 commands: the phases test below holds each phase by default
def test_sigint_at_any_moment_of_every_long_command(tmp_path: Path) -> None:
    """7 commands x 20 points, 4 at a time, each DDS one in a ROS domain of its own; the span
    of the points is each command's own uninterrupted run, measured first."""
    domains = Domains()
    with ThreadPoolExecutor(AT_ONCE) as pool:
        whole = dict(zip(COMMANDS, pool.map(
            lambda c: domains.run(c, None, tmp_path / c.name / "whole"), COMMANDS),
            strict=True))
        for command, outcome in whole.items():
            assert outcome.code == 0 and outcome.left == [], (command.name, outcome.stderr)
        cases = []
        for command in COMMANDS:
            rng = random.Random(f"{SEED} {command.name}")
            span = whole[command].point_s
            points = [0.0] + [rng.uniform(0, span) for _ in range(POINTS - 1)]
            cases += [(command, point, tmp_path / command.name / str(n))
                      for n, point in enumerate(points)]
        outcomes = list(pool.map(lambda case: domains.run(*case), cases))
    for outcome in outcomes:
        check(outcome)
    delivered = {c.name: sum(o.delivered for o in outcomes if o.command == c.name)
                 for c in COMMANDS}
    print("points before the end (the rest after it):", delivered)
    assert all(n >= POINTS // 2 for n in delivered.values()), delivered


PHASES = """
import signal, sys, time
from stillframe import interrupts
phase = sys.argv[1]
interrupts.starting("prog")
if phase == "finish":
    interrupts.working()
    print("done", flush=True)
    interrupts.ending("prog")
if phase == "starting" or phase == "finish":
    signal.raise_signal(signal.SIG{sig})
    time.sleep(5)


def work():
    if phase == "working":
        signal.raise_signal(signal.SIG{sig})
        time.sleep(5)
    if phase == "converted":        # as a C extension's initialisation turns it
        try:
            signal.raise_signal(signal.SIG{sig})
            time.sleep(5)
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc
    if phase == "swallowed":        # as a library's bare except ends it
        try:
            signal.raise_signal(signal.SIG{sig})
            time.sleep(5)
        except BaseException:
            pass
    if phase == "answered":         # as launch answers it: its own line and code
        try:
            signal.raise_signal(signal.SIG{sig})
            time.sleep(5)
        except KeyboardInterrupt as exc:
            print("prog: interrupted; every node stopped", file=sys.stderr, flush=True)
            return interrupts.exit_code(exc)
    if phase == "finaliser":
        class Finalised:
            def __del__(self):
                signal.raise_signal(signal.SIG{sig})    # the handler runs inside __del__
                sum(range(1000))
        Finalised()
        for _ in range(10**7):      # bytecode the interruption can come back in
            pass
    print("not interrupted", flush=True)
    return 0


interrupts.working()
code = interrupts.run_work("prog", work)
print("exit", code, flush=True)
sys.exit(code)
"""


@pytest.mark.parametrize("sig", ["INT", "TERM"])
@pytest.mark.parametrize(("phase", "out"), [
    ("starting", ""),
    ("working", "exit {code}\n"),
    ("converted", "exit {code}\n"),
    ("swallowed", "not interrupted\nexit {code}\n"),
    ("finaliser", "exit {code}\n"),
    ("answered", "exit {code}\n"),
    ("finish", "done\n"),
])
def test_each_phase_answers_a_signal(sig: str, phase: str, out: str) -> None:
    """Starting and ending: the line and 128 + the signal at once. Working: the same once the
    work has unwound, whether the KeyboardInterrupt (SIGTERM: Terminated) came back as one,
    turned into another error, was swallowed by the work, or was raised in a finaliser (which
    Python would have printed and dropped); a work that answered it with its own line and
    code gets no second line."""
    signum = getattr(signal, f"SIG{sig}")
    done = subprocess.run([sys.executable, "-c", PHASES.format(sig=sig), phase],
                          env=child_env(), cwd=REPO_ROOT, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 128 + signum, done.stderr
    assert done.stdout == out.format(code=128 + signum)
    assert done.stderr == ("prog: interrupted; every node stopped\n" if phase == "answered"
                           else "prog: interrupted\n")
