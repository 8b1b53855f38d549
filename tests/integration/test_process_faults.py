"""Process faults, LQG through the three node processes, timed in sample periods from a bag
recorded by ``stillframe record``. Steps 1-3 run in real time: in lock-step the simulator never
advances without the command of the current sample, so a peer that dies ends a lock-step run
(tests/integration/test_lockstep_faults.py); in real time the loop goes on, and these are its
safe states:

1. the estimator is killed (SIGKILL): the controller's command is zero within 3 sample periods
   of the last estimate (its watchdog), the sim keeps running, the controller's ``/diagnostics``
   is ERROR naming the watchdog;
2. the estimator is restarted: it starts from the current measurements (its first estimate of φ
   is the encoder's reading, within 1e-2 rad of the truth, and so are those of the next 2 s, each
   made with every reading of its sample: ``partial_after_s`` is long) and control resumes;
3. the controller is killed: the sim holds the newest command it took, then applies zero once
   that is 3 periods old (``command_timeout_periods``; the miss-rate guard is off here, so that
   the safe state alone acts, whatever deadlines the machine's load made the loop miss before).

The estimator is restarted while the loop runs (the run lasts 600 s of real time, so that it
cannot end before the estimator is back however slow the machine is); it names the sample it
started from in its log.

4. the sim is killed (lock-step): the estimator and controller idle and report stale input; a new
   sim (at t = 0 again) is taken as a restart and the loop resumes at once. The estimator and
   controller take their inputs from the writers of the nodes named (``sensor_writer:=sim_node``,
   ``estimate_writer:=estimator_node``): the new sim's writers (new GIDs) are taken, none
   refused. (Steps 1-3 take them from the first writer seen: the controller takes the restarted
   estimator's, so control resumes.)
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from stillframe.bags.storage import read_bag
from stillframe.contract import messages, topics
from stillframe.contract.codecs import applied_torque, physical_state
from stillframe.contract.messages import TYPESTORE
from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.middleware.api import create_node, spin_until
from tests.support.middleware import child_env, finish
from tests.support.nodes import Statuses, params_file, start_node, stop
from tests.support.scenes import thesis_scene
from tests.support.waits import HANG_S

RATE_HZ = 32.0
PERIOD_NS = round(1e9 / RATE_HZ)
RECORDED = ["/frame/state_estimate", "/frame/pendulum/torque_cmd", "/frame/state_truth",
            "/frame/pendulum/joint_states"]
OVERRIDES = ["duration=600", "controller.start=1", "evaluation.window=1"]
PARTIAL_AFTER_S = 30.0      # far beyond any stall of a loaded machine


class Watch:
    """The test's own node: the newest /clock and every controller status."""

    def __init__(self) -> None:
        self.node = create_node("fault_probe", argv=["test"])
        self.clock_ns = 0
        self.levels: list[int] = []
        self.node.create_subscription(topics.CLOCK.type_name, "/clock", self.on_clock, "clock")
        self.node.create_subscription(topics.DIAGNOSTICS.type_name, "/diagnostics",
                                      self.on_status, "default")

    def on_clock(self, msg: object) -> None:
        self.clock_ns = messages.stamp_ns(msg.clock)

    def on_status(self, msg: object) -> None:
        self.levels += [s.level for s in msg.status if s.name == "/frame/controller_node"]

    def until(self, condition: object, timeout: float = 60) -> None:
        assert spin_until(self.node, condition, timeout)

    def estimator_reads(self) -> bool:
        """An estimator subscribes the sensor topics (the restarted one is up)."""
        return any(ep.node_name == "estimator_node"
                   for ep in self.node.get_subscriptions_info_by_topic("/frame/floor1/imu"))


def _by_topic(bag: Path) -> dict[str, list]:
    out: dict[str, list] = {t: [] for t in RECORDED}
    for m in read_bag(bag, TYPESTORE, decode=True):
        out[m.topic].append((messages.stamp_ns(m.msg.header.stamp), m.msg))
    return out


@pytest.mark.slow
def test_kill_and_restart_estimator_then_kill_controller(ros_domain: int, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    # the estimator waits for every reading of a sample (PARTIAL_AFTER_S): a restarted filter
    # that does not yet know the velocities drifts by φ' T in a period without the encoder's
    # reading, and a loaded machine's late reading must not be what step 2 measures
    params = params_file(tmp_path, "thesis_lqg", OVERRIDES, mode="realtime",
                         command_miss_limit=0.0, diagnostics_period_s=0.05,
                         await_recorder=RECORDED, partial_after_s=PARTIAL_AFTER_S)
    recorder = subprocess.Popen([sys.executable, "-m", "stillframe", "record", "-o", str(bag),
                                 *RECORDED], env=child_env(), cwd=REPO_ROOT,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    estimator = start_node("estimator_node", params)
    controller = start_node("controller_node", params)
    sim = start_node("sim_node", params)
    watch = Watch()
    statuses = Statuses(watch.node)
    procs = [recorder, estimator, controller, sim]
    try:
        watch.until(lambda: watch.clock_ns >= 3e9)
        estimator.kill()                                           # 1. SIGKILL the estimator
        estimator.wait()
        gone_at = watch.clock_ns
        watch.until(lambda: 2 in watch.levels)                     # the controller says ERROR
        watch.until(lambda: watch.clock_ns >= gone_at + 10 * PERIOD_NS)
        estimator = start_node("estimator_node", params)           # 2. restart it
        procs.append(estimator)
        watch.until(watch.estimator_reads)
        seen = len(watch.levels)
        watch.until(lambda: len(watch.levels) > seen + 2 and watch.levels[-1] == 0)
        resumed = watch.clock_ns
        watch.until(lambda: watch.clock_ns >= resumed + 2e9)
        values = statuses.latest.get("/frame/estimator_node", (0, "", {}))[2]
        counts = {k: values.get(k) for k in ("partial_updates", "late_inputs", "refilters")}
        controller.kill()                                          # 3. SIGKILL the controller
        controller.wait()
        killed = watch.clock_ns
        watch.until(lambda: watch.clock_ns >= killed + 10 * PERIOD_NS)
    finally:
        watch.node.destroy_node()
        logs = {proc: stop(proc)[1] for proc in (sim, estimator, controller)
                if proc.poll() is None}
        recorder.send_signal(signal.SIGINT)
        finish(recorder)
        for proc in procs:
            if proc.poll() is None:
                proc.kill()

    got = _by_topic(bag)
    estimates = [ns for ns, _ in got["/frame/state_estimate"]]
    # the restarted estimator names the sample it started from
    joined = re.search(r"started from the measurements at t = (\S+) s", logs[estimator])
    assert joined, logs[estimator]
    first_after = round(float(joined[1]) * 1e9)
    last_estimate = max(ns for ns in estimates if ns < first_after)
    assert first_after - last_estimate > 3 * PERIOD_NS            # the estimator was gone
    commands = {ns: m.wrench.torque.z for ns, m in got["/frame/pendulum/torque_cmd"]}
    # the watchdogs: no command stamped more than the controller's timeout (3 periods) after
    # the last estimate holds a torque, and the torque the sim applies (effort, for the period
    # before its stamp) is zero from its own command timeout on (3 periods, one more for the
    # period the effort covers). When the controller's first zero comes depends on when the
    # loaded machine runs it (it may send none while the estimator is gone); that no stale
    # torque is sent or applied does not.
    late = [v for ns, v in commands.items() if last_estimate + 3 * PERIOD_NS < ns < first_after]
    encoder = dict(got["/frame/pendulum/joint_states"])
    efforts = {ns: m.effort[0] for ns, m in encoder.items()}
    applied = [v for ns, v in efforts.items() if last_estimate + 4 * PERIOD_NS < ns < first_after]
    print(f"estimator killed: {len(late)} commands while it was gone, "
          f"{sum(v != 0.0 for v in late)} not zero; {len(applied)} samples applied, "
          f"{sum(v != 0.0 for v in applied)} not zero")
    assert all(v == 0.0 for v in late)
    assert applied and all(v == 0.0 for v in applied)
    # control was on before: the commands of the last ten periods (the one for the last estimate
    # may never be sent when the kill lands between the estimate's two readers)
    assert any(v != 0.0 for ns, v in commands.items()
               if last_estimate - 10 * PERIOD_NS <= ns <= last_estimate)
    truth = dict(got["/frame/state_truth"])
    stamps = sorted(truth)
    during = [ns for ns in stamps if last_estimate <= ns <= first_after]
    assert np.all(np.diff(during) == PERIOD_NS)                   # the sim kept running
    # 2. restarted from the measurements: its first estimate is the sample's own, φ the encoder's
    # reading (noise 1e-3 rad), whatever the pendulum's speed; its covariance allows for the
    # velocities it does not know, so the next 2 s stay within 10 noise deviations too
    estimated = dict(got["/frame/state_estimate"])
    first = physical_state(estimated[first_after])
    true_phi = physical_state(truth[first_after])[3]
    following = [abs(physical_state(estimated[ns])[3] - physical_state(truth[ns])[3])
                 for ns in estimates if first_after < ns <= first_after + 64 * PERIOD_NS]
    print(f"restarted estimator: first φ error {first[3] - true_phi:.2e} rad (φ = {true_phi:.3f}),"
          f" largest of the next {len(following)}: {max(following):.2e} rad; {counts}")
    assert first[3] == encoder[first_after].position[0]
    assert abs(first[3] - true_phi) < 1e-2
    assert len(following) >= 32 and max(following) < 1e-2, (following, counts)
    assert any(v != 0.0 for ns, v in commands.items() if ns > first_after)   # control resumed
    # 3. the controller killed: the applied torque (effort, reported at t for [t - T, t)). The
    # newest command the sim took is the recorder's last, or one period after it (the SIGKILL
    # may cut its last write short between the two readers); taken late in real time, it is
    # applied from the period after its own. Either way it is held (not zero at once), and zero
    # is applied once it is 3 periods old: reported from 5 periods after the recorder's last
    last_command = max(commands)
    effort = {ns: applied_torque(m) for ns, m in got["/frame/pendulum/joint_states"]}
    print(f"controller killed: last command recorded at {last_command}")
    held = [effort[ns] for ns in effort if last_command < ns <= last_command + 3 * PERIOD_NS]
    assert any(v != 0.0 for v in held), held
    after = [v for ns, v in effort.items() if ns >= last_command + 5 * PERIOD_NS]
    assert len(after) >= 5 and all(v == 0.0 for v in after)


def _cpu_s(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far [s] (/proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.mark.slow
def test_sim_killed_loop_idles_reports_stale_input_and_resumes_with_a_new_sim(
        ros_domain: int, tmp_path: Path) -> None:
    """The sim is SIGKILLed mid-run: the estimator and controller idle (CPU over 1 s of wall time
    below half a core, a generous bound for a node that blocks in its wait set), say ERROR
    'stale input' in /diagnostics; a new sim starting at t = 0 is taken as a restart of the loop
    (``time_jumps``), and its whole run equals the one-process loop to the last bit: the
    estimator started again from the scene, control resumed at the new run's sample 0."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = params_file(tmp_path / "a", "thesis_lqg", OVERRIDES,
                        diagnostics_period_s=0.05, sensor_writer="sim_node",
                        estimate_writer="estimator_node")
    short = ["duration=4", "controller.start=1", "evaluation.window=1"]
    result = tmp_path / "b" / "result.json"
    second = params_file(tmp_path / "b", "thesis_lqg", short,
                         diagnostics_period_s=0.05, result_file=str(result))
    estimator = start_node("estimator_node", first)
    controller = start_node("controller_node", first)
    sim = start_node("sim_node", first)
    watch = Watch()
    statuses = Statuses(watch.node)
    peers = (estimator, controller)
    try:
        watch.until(lambda: watch.clock_ns >= 3e9)
        sim.kill()                                                 # SIGKILL the sim
        sim.wait()
        watch.until(lambda: all(statuses.stale(n) for n in ("estimator_node", "controller_node")),
                    timeout=HANG_S)
        before = [_cpu_s(p.pid) for p in peers]
        spin_until(watch.node, lambda: False, 1.0)
        used = [_cpu_s(p.pid) - b for p, b in zip(peers, before, strict=True)]
        print(f"sim killed: CPU over 1 s estimator {used[0]:.3f} s, controller {used[1]:.3f} s")
        assert max(used) < 0.5
        sim = start_node("sim_node", second)                       # a new sim, t = 0 again
        _out, err = finish(sim, timeout=120)
        assert sim.returncode == 0, err[-2000:]
        spin_until(watch.node, lambda: False, 0.5)
    finally:
        watch.node.destroy_node()
        for proc in (sim, *peers):
            if proc.poll() is None:
                stop(proc)
    estimator_values = statuses.latest["/frame/estimator_node"][2]
    controller_values = statuses.latest["/frame/controller_node"][2]
    assert estimator_values["time_jumps"] == "1" and controller_values["time_jumps"] == "1"
    # the new sim's writers taken by the name pinned, none refused
    assert estimator_values["refused_writers"] == controller_values["refused_writers"] == "0"
    assert estimator_values["floor1_imu_writer"] == "/frame/sim_node"
    assert controller_values["excitation_wrench_writer"] == "/frame/sim_node"
    with np.load(result.with_suffix(".npz")) as data:
        hist = dict(data)
    reference = run_closed_loop(thesis_scene("thesis_lqg", short))
    np.testing.assert_array_equal(hist["truth"], reference.truth)
    np.testing.assert_array_equal(hist["command"], reference.command)
    assert json.loads(result.read_text())["complete"] is True
