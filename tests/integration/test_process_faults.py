"""Process faults (issue 11, item 3), lock-step LQG through the three node processes, timed in
sample periods from a bag recorded by ``stillframe record``:

1. the estimator is killed (SIGKILL): the controller's command is zero within 3 sample periods
   of the last estimate (its watchdog), the sim keeps running, the controller's ``/diagnostics``
   is ERROR naming the watchdog;
2. the estimator is restarted: it starts from the current measurements (its first estimate of φ
   within 1e-2 rad of the truth) and control resumes;
3. the controller is killed: the applied torque the sim reports (the encoder's ``effort``) is the
   last command until that is 3 periods old (``command_timeout_periods``), zero from then on.

The loop is frozen (SIGSTOP on the sim) while the estimator restarts, so that the run cannot end
before it is back however fast the machine is.
"""

from __future__ import annotations

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
from stillframe.middleware.api import create_node, spin_until
from tests.support.middleware import child_env, finish
from tests.support.nodes import params_file, start_node, stop, wait_for_log

RATE_HZ = 32.0
PERIOD_NS = round(1e9 / RATE_HZ)
RECORDED = ["/frame/state_estimate", "/frame/pendulum/torque_cmd", "/frame/state_truth",
            "/frame/pendulum/joint_states"]
OVERRIDES = ["duration=600", "controller.start=1", "evaluation.window=1"]


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


def _by_topic(bag: Path) -> dict[str, list]:
    out: dict[str, list] = {t: [] for t in RECORDED}
    for m in read_bag(bag, TYPESTORE, decode=True):
        out[m.topic].append((messages.stamp_ns(m.msg.header.stamp), m.msg))
    return out


@pytest.mark.slow
def test_kill_and_restart_estimator_then_kill_controller(ros_domain: int, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    params = params_file(tmp_path, "thesis_lqg", OVERRIDES, lockstep_timeout_s=0.2,
                         diagnostics_period_s=0.05, await_recorder=RECORDED)
    recorder = subprocess.Popen([sys.executable, "-m", "stillframe", "record", "-o", str(bag),
                                 *RECORDED], env=child_env(), cwd=REPO_ROOT,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    estimator = start_node("estimator_node", params)
    controller = start_node("controller_node", params)
    sim = start_node("sim_node", params)
    watch = Watch()
    procs = [recorder, estimator, controller, sim]
    try:
        watch.until(lambda: watch.clock_ns >= 3e9)
        estimator.kill()                                           # 1. SIGKILL the estimator
        estimator.wait()
        watch.until(lambda: 2 in watch.levels)                     # the controller says ERROR
        sim.send_signal(signal.SIGSTOP)                            # freeze the loop
        estimator = start_node("estimator_node", params)           # 2. restart it
        procs.append(estimator)
        wait_for_log(estimator, "waiting for the controller")
        spin_until(watch.node, lambda: False, 1.0)
        sim.send_signal(signal.SIGCONT)
        seen = len(watch.levels)
        watch.until(lambda: len(watch.levels) > seen + 2 and watch.levels[-1] == 0)
        resumed = watch.clock_ns
        watch.until(lambda: watch.clock_ns >= resumed + 2e9)
        controller.kill()                                          # 3. SIGKILL the controller
        controller.wait()
        killed = watch.clock_ns
        watch.until(lambda: watch.clock_ns >= killed + 10 * PERIOD_NS)
    finally:
        watch.node.destroy_node()
        for proc in (sim, estimator, controller):
            if proc.poll() is None:
                stop(proc)
        recorder.send_signal(signal.SIGINT)
        finish(recorder, timeout=30)
        for proc in procs:
            if proc.poll() is None:
                proc.kill()

    got = _by_topic(bag)
    estimates = [ns for ns, _ in got["/frame/state_estimate"]]
    gap = int(np.argmax(np.diff(estimates)))
    last_estimate, first_after = estimates[gap], estimates[gap + 1]
    assert first_after - last_estimate > 3 * PERIOD_NS            # the estimator was gone
    commands = {ns: m.wrench.torque.z for ns, m in got["/frame/pendulum/torque_cmd"]}
    zero_at = min(ns for ns, v in commands.items() if last_estimate < ns and v == 0.0)
    periods_to_zero = (zero_at - last_estimate) / PERIOD_NS
    print(f"estimator killed: zero command {periods_to_zero:g} periods after the last estimate")
    assert periods_to_zero <= 3
    assert commands[last_estimate] != 0.0                         # control was on before
    truth = dict(got["/frame/state_truth"])
    stamps = sorted(truth)
    during = [ns for ns in stamps if last_estimate <= ns <= first_after]
    assert np.all(np.diff(during) == PERIOD_NS)                   # the sim kept running
    # 2. restarted from the measurements: φ of its first estimate against the truth
    first = physical_state(dict(got["/frame/state_estimate"])[first_after])
    true_phi = physical_state(truth[first_after])[3]
    print(f"restarted estimator: first φ error {first[3] - true_phi:.2e} rad (φ = {true_phi:.3f})")
    assert abs(first[3] - true_phi) < 1e-2
    assert any(v != 0.0 for ns, v in commands.items() if ns > first_after)   # control resumed
    # 3. the controller killed: the applied torque (effort, over the previous period)
    last_command = max(commands)
    effort = {ns: applied_torque(m) for ns, m in got["/frame/pendulum/joint_states"]}
    # the newest command taken is held (nonzero) until it is 3 periods old ...
    assert all(effort[last_command + k * PERIOD_NS] != 0.0 for k in (1, 2, 3))
    # ... then zero (applied over [t + 3 periods, t + 4 periods), reported at t + 4 periods)
    after = [v for ns, v in effort.items() if ns >= last_command + 4 * PERIOD_NS]
    assert len(after) >= 5 and all(v == 0.0 for v in after)
