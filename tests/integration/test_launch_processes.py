"""``stillframe launch``'s process handling, with stand-in nodes (tiny scripts) in place of the
real ones: the stand-ins shadow the packages because a child started with ``python -m`` puts its
working directory first on ``sys.path``. What is checked: the command line the nodes get, the
JSON passed through, Ctrl-C and a killed node stopping every child (no orphans, checked with
``os.kill(pid, 0)``), and the exit codes."""

from __future__ import annotations

import io
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from stillframe.app.launcher import NODES, StatusLine, node_command, status_text
from stillframe.locations import REPO_ROOT
from stillframe.middleware.params import node_overrides, parse_ros_args
from tests.support.middleware import run_stillframe
from tests.support.waits import HANG_S

SCENE = REPO_ROOT / "scenes" / "thesis_lqg.yaml"

SIM = """\
import json, os, signal, sys, time
args = dict(a.split(":=", 1) for a in sys.argv if ":=" in a)
def stop(*_):
    # as the real sim_node: interrupted, it writes the samples it ran, marked incomplete
    with open(args["result_file"], "w") as f:
        json.dump({{"complete": False, "steps": 7, "steps_planned": 1600}}, f)
    sys.exit(0)
signal.signal(signal.SIGINT, stop)
print("sim argv", json.dumps(sys.argv[1:]), flush=True)
open("sim_node.up", "w").close()
deadline = time.monotonic() + 600   # conditions to wait for, forced rather than timed
while not all(map(os.path.exists, {wait_for!r})) and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(float({sim_seconds!r}))
with open(args["result_file"], "w") as f:
    json.dump({result!r}, f)
"""
#: a node that waits for SIGINT (exit 0), or exits with ``code`` ``life`` seconds after every
#: stand-in has started (so that each has printed its first line before one ends the run)
WAITER = """\
import os, signal, sys, time
signal.signal(signal.SIGINT, lambda *a: sys.exit(0))
print("waiting", flush=True)
open(__package__ + ".up", "w").close()
deadline = time.monotonic() + 600
while not all(map(os.path.exists, {up!r})) and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep({life!r})
sys.exit({code!r})
"""
#: the files the stand-ins write once they have printed their first line
UP = tuple(f"{name}.up" for name in NODES)
#: a controller that reports once, as it stops (a real node's last status counts the whole run)
STATUS_AT_STOP = """\
from stillframe.contract import topics
from stillframe.node_runtime.support import Diagnostics
from stillframe.middleware import api
node = api.create_node("controller_node", namespace=topics.DEFAULT_NAMESPACE)
diagnostics = Diagnostics(node, 3600.0)
api.spin_until(node, lambda: diagnostics.pub.get_subscription_count() > 0, 60)
open("controller_matched", "w").close()     # the stand-in simulator ends only after this
print("waiting", flush=True)
while api.ok():
    node.spin_once(0.1)
diagnostics.publish(0, {{"watchdog": 7}})
diagnostics.pub.wait_for_all_acked(10.0)
"""
RESULT = {"reduction_pct": {"displacement": [71.0, 75.0, 57.0], "velocity": [73.0, 80.0, 70.0]},
          "peak_command": 0.25, "complete": True, "steps": 1600, "wall_s": 1.0}


def write_stand_ins(root: Path, sim_seconds: float = 1.0, life: float = 3600,
                    code: int = 0, wait_for: tuple[str, ...] = UP) -> None:
    """Packages sim_node/estimator_node/controller_node with a ``__main__`` module each (what
    the launcher runs): the sim writes RESULT ``sim_seconds`` after the files ``wait_for``
    exist (by default: after every stand-in has started); the others wait for SIGINT (exit 0)
    or exit with ``code`` ``life`` seconds after every stand-in has started."""
    for name in NODES:
        (root / name).mkdir()
        (root / name / "__init__.py").write_text("")
    (root / "sim_node" / "__main__.py").write_text(
        SIM.format(sim_seconds=sim_seconds, result=RESULT, wait_for=wait_for))
    (root / "estimator_node" / "__main__.py").write_text(
        WAITER.format(life=3600, code=0, up=UP))
    (root / "controller_node" / "__main__.py").write_text(
        WAITER.format(life=life, code=code, up=UP))


def start_launch(cwd: Path, *args: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT), PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "stillframe", "launch", str(SCENE), *args],
                            cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def wait_for_children(proc: subprocess.Popen, count: int = 3,
                      timeout: float = 600) -> tuple[dict[str, int], list[str]]:
    """Read the launcher's stderr until ``count`` children announced their pid and every one
    printed its first line (``timeout`` only ends a hang: a loaded machine starts them late)."""
    pids: dict[str, int] = {}
    lines: list[str] = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line and proc.poll() is not None:
            break
        lines.append(line)
        if m := re.search(r"started (\w+) \(pid (\d+)\)", line):
            pids[m.group(1)] = int(m.group(2))
        talked = {n for n in pids if any(s.startswith(f"[{n}]") for s in lines)}
        if len(pids) == count and talked == set(pids):
            return pids, lines
    proc.kill()
    raise AssertionError(f"children did not start: {lines}")


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_node_command_passes_overrides_through_the_ros_parameter_parser() -> None:
    """The nodes read ``overrides`` with the ROS argument parser: each ``key=value`` arrives
    whole, including list values and values with spaces."""
    overrides = ["duration=4", "plant.process_noise_std=[0, 0, 0, 0, 0, 0, 0, 0]",
                 "description=a b: c"]
    argv = node_command("sim_node", Path("/s/scene.yaml"), overrides, "lockstep",
                        params={"result_file": "/tmp/r.json", "lockstep_timeout_s": 2.0})
    assert argv[1:3] == ["-m", "sim_node"]
    params = node_overrides(parse_ros_args(argv[3:]), "/sim_node")
    assert params == {"scene": "/s/scene.yaml", "mode": "lockstep", "overrides": overrides,
                      "result_file": "/tmp/r.json", "lockstep_timeout_s": 2.0}
    # no overrides: no parameter at all (a ROS parameter cannot be an empty array)
    plain = node_overrides(parse_ros_args(node_command("x", Path("/s"), [], "realtime")[3:]), "/x")
    assert plain == {"scene": "/s", "mode": "realtime"}


def test_status_text_orders_nodes_and_cuts_to_width() -> None:
    statuses = {"controller_node: loop": {"saturated": "0", "compute_ms_p50": "0.1"},
                "/frame/sim_node": {"sim_time_s": "12.5", "step": "400", "deadline_misses": "0",
                                    "latency_ms_p50": "0.2"},
                "/frame/estimator_node": {"rejected": "1"},
                "other": {"a": "b"}}
    line = status_text(statuses)
    assert line == ("sim_node: sim_time_s=12.5 step=400 deadline_misses=0 | "
                    "estimator_node: rejected=1 | loop: saturated=0 | other: a=b")
    short = status_text(statuses, width=20)
    assert len(short) == 20 and short.endswith("…")


def test_launch_passes_sim_nodes_result_through_and_stops_the_others(
        tmp_path: Path, ros_domain: int) -> None:
    write_stand_ins(tmp_path)
    proc = start_launch(tmp_path, "--json", "--set", "duration=60", "--mode", "realtime")
    pids, lines = wait_for_children(proc)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert json.loads(out) == {"scene": "thesis_lqg", **RESULT, "degraded": False,
                               "degraded_reasons": [], "foreign_writers": [], "diagnostics": {}}
    err = "".join(lines) + err
    sim_argv = json.loads(next(line for line in err.splitlines() if "sim argv" in line)
                          .split("sim argv ", 1)[1])
    # the resolved scene (duration 60 in it), no overrides to apply again
    assert "mode:=realtime" in sim_argv and not any("overrides:=" in a for a in sim_argv)
    assert any(a.startswith("scene:=") and a.endswith("/scene.resolved.yaml") for a in sim_argv)
    # the run's token (docs/nodes.md, writer identity): 64 random bits
    assert sum(bool(re.fullmatch(r"run_token:=t[0-9a-f]{16}", a)) for a in sim_argv) == 1
    assert not any(alive(pid) for pid in pids.values())


def test_the_nodes_last_statuses_written_as_they_stop_are_in_the_result(
        tmp_path: Path, ros_domain: int) -> None:
    """The controller reports only after the launcher stopped it (forced: its status period is
    an hour): the launcher still takes that status before it returns. The stand-in simulator
    ends only once the controller's status writer matched the launcher's reader (forced: it
    waits for the file the controller writes then, not for a time that a loaded machine may
    not keep)."""
    write_stand_ins(tmp_path, sim_seconds=0.2, wait_for=("controller_matched",))
    (tmp_path / "controller_node" / "__main__.py").write_text(STATUS_AT_STOP.format())
    proc = start_launch(tmp_path, "--json", "--mode", "realtime")
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert json.loads(out)["diagnostics"]["/frame/controller_node"]["watchdog"] == "7"


def test_ctrl_c_stops_every_child(tmp_path: Path, ros_domain: int) -> None:
    write_stand_ins(tmp_path, sim_seconds=3600)
    proc = start_launch(tmp_path)
    pids, _ = wait_for_children(proc)
    assert all(alive(pid) for pid in pids.values())
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err
    assert "interrupted; every node stopped" in err
    assert not any(alive(pid) for pid in pids.values())


@pytest.mark.parametrize("how", ["killed", "exit"])
def test_a_dead_node_is_named_and_the_rest_stopped(
        tmp_path: Path, ros_domain: int, how: str) -> None:
    """The others are stopped cleanly (SIGINT, exit 0), and what the run has is kept: the
    simulator's partial result, marked incomplete, with the dead node and how, on stdout
    (``--json``) and under ``--out``; exit 1."""
    write_stand_ins(tmp_path, sim_seconds=3600, life=3600 if how == "killed" else 1, code=3)
    proc = start_launch(tmp_path, "--json", "--out", "out")
    pids, _ = wait_for_children(proc)
    if how == "killed":
        os.kill(pids["controller_node"], signal.SIGKILL)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 1, err
    expected = "killed by SIGKILL" if how == "killed" else "exit code 3"
    assert f"stillframe launch: error: controller_node died ({expected})" in err
    assert not any(alive(pid) for pid in pids.values())
    partial = {"complete": False, "steps": 7, "steps_planned": 1600,
               "died": {"node": "controller_node", "how": expected},
               "stopped": {"sim_node": "exit code 0", "estimator_node": "exit code 0"},
               "diagnostics": {}}
    assert json.loads(out) == {"scene": "thesis_lqg", **partial}
    assert json.loads((tmp_path / "out" / "result.json").read_text()) == partial


def test_a_killed_simulator_still_leaves_the_statuses_and_who_died(
        tmp_path: Path, ros_domain: int) -> None:
    """The simulator itself SIGKILLed: no samples to keep, and the partial result says so (no
    ``steps``), with who died and how the others stopped; exit 1."""
    write_stand_ins(tmp_path, sim_seconds=3600)
    proc = start_launch(tmp_path, "--out", "out")
    pids, _ = wait_for_children(proc)
    os.kill(pids["sim_node"], signal.SIGKILL)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 1, err
    assert "stillframe launch: error: sim_node died (killed by SIGKILL)" in err
    assert "partial result (complete: false): no samples; written to out/result.json" in out
    assert json.loads((tmp_path / "out" / "result.json").read_text()) == {
        "complete": False, "died": {"node": "sim_node", "how": "killed by SIGKILL"},
        "stopped": {"estimator_node": "exit code 0", "controller_node": "exit code 0"},
        "diagnostics": {}}


def test_killed_launcher_leaves_no_orphans(tmp_path: Path, ros_domain: int) -> None:
    """SIGKILL cannot be forwarded: the children's parent-death signal (prctl) ends them."""
    write_stand_ins(tmp_path, sim_seconds=3600)
    proc = start_launch(tmp_path)
    pids, _ = wait_for_children(proc)
    proc.kill()
    proc.communicate(timeout=HANG_S)
    deadline = time.monotonic() + HANG_S
    while any(alive(pid) for pid in pids.values()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(alive(pid) for pid in pids.values())


@pytest.mark.parametrize(("args", "message"), [
    (["launch", str(SCENE), "--record-topic", "/frame/floor1/imu"],
     "stillframe launch: error: --record-topic needs --record DIR"),
    (["launch", str(SCENE), "--record", str(REPO_ROOT / "bags" / "hammer")],
     f"stillframe launch: error: --record {REPO_ROOT / 'bags' / 'hammer'}: already exists"),
    (["launch", str(SCENE), "--set", "duration=-1"],
     "stillframe launch: error: duration: must lie in (0, 1e+06] (got -1.0)"),
    (["reproduce", str(REPO_ROOT / "scenes" / "hammer_test.yaml")],
     f"stillframe reproduce: error: {REPO_ROOT / 'scenes' / 'hammer_test.yaml'}: "
     "controller.type: the scene has no controller to evaluate"),
])
def test_bad_input_is_one_line_and_exit_2_before_any_process(
        args: list[str], message: str, ros_domain: int) -> None:
    done = run_stillframe(*args)
    assert done.returncode == 2
    assert done.stderr.strip() == message


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_status_line_plain_every_period_and_live_in_place() -> None:
    plain = io.StringIO()
    status = StatusLine(plain, every_s=3600)
    status.update("sim_node: step=1")
    status.update("sim_node: step=2")          # within the period: not printed
    status.echo("[sim_node] hello")
    assert plain.getvalue() == "sim_node: step=1\n[sim_node] hello\n"
    live = FakeTerminal()
    status = StatusLine(live)
    status.update("step=1")
    status.echo("[x] line")                     # printed above, the status line redrawn
    status.close()
    assert live.getvalue() == "\r\x1b[Kstep=1\r\x1b[K[x] line\nstep=1\r\x1b[K"
