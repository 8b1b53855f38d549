"""Managed (lifecycle) nodes: the estimator and the controller as rcl_lifecycle nodes on both
backends, driven through the standard ``lifecycle_msgs`` services while the lock-step loop runs.

References: the state machine of the ``dds`` backend against rclpy's own (rcl_lifecycle's
transition graph and states, read from a real ``rclpy.lifecycle.LifecycleNode``); a deactivated
controller commands exactly 0 (the supervisor's disabled output) and the LQG law's commands of
``thesis_lqg`` after ``controller.start`` are far from 0.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from stillframe.app import cli
from stillframe.middleware import lifecycle
from tests.support.middleware import run_stillframe
from tests.support.nodes import params_file, start_node, stop
from tests.support.rclpy_client import RclpyClient, rclpy_client

OVERRIDES = ["duration=5000", "controller.start=1", "evaluation.window=1"]
#: commands a client may read on the other side of a transition's reply (lock-step: each is a
#: round trip of the loop, so at most a few are on the way)
IN_FLIGHT = 3


def start_loop(tmp_path: Path) -> list[Any]:
    """The three nodes, the managed two with ``autostart`` false (as ``stillframe launch``
    starts them): they wait unconfigured for a client's transitions."""
    params = params_file(tmp_path, "thesis_lqg", OVERRIDES, autostart=False)
    return [start_node(name, params) for name in ("estimator_node", "controller_node", "sim_node")]


def test_the_dds_state_machine_is_rcl_lifecycles() -> None:
    """The ``dds`` backend's graph, states and refusals against rclpy's LifecycleNode."""
    rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (the ros extra)")
    from rclpy.context import Context
    from rclpy.lifecycle import LifecycleNode

    context = Context()
    rclpy.init(context=context)
    try:
        node = LifecycleNode("graph_reference", context=context)
        machine = node._state_machine
        assert [tuple(t) for t in lifecycle.GRAPH] == [
            (t[0], t[1], t[2], t[4]) for t in machine.transition_graph]
        assert dict(machine.available_states) == lifecycle.STATE_LABELS
        ours = lifecycle.StateMachine(lambda _: lifecycle.SUCCESS)
        for label in ("configure", "activate", "deactivate", "cleanup", "shutdown"):
            assert {(t.id, t.label) for t in ours.available()} == {
                (t[0], t[1]) for t in machine.available_transitions}
            with pytest.raises(lifecycle.TransitionRefusedError, match="No transition matching"):
                ours.change(label="bogus")
            ours.change(label=label)
            getattr(node, f"trigger_{label}")()
            assert ours.state == machine.current_state[0]
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_a_failing_callback_goes_back_and_an_error_through_errorprocessing() -> None:
    outcomes = iter([lifecycle.FAILURE, lifecycle.ERROR, lifecycle.SUCCESS])
    events: list[lifecycle.Transition] = []
    machine = lifecycle.StateMachine(lambda _: next(outcomes), events.append)
    assert machine.change(label="configure") == lifecycle.FAILURE
    assert machine.label == "unconfigured"
    assert machine.change(label="configure") == lifecycle.ERROR   # on_error: success
    assert machine.label == "unconfigured"
    assert [(e.start, e.goal) for e in events][-3:] == [
        (lifecycle.UNCONFIGURED, lifecycle.CONFIGURING),
        (lifecycle.CONFIGURING, lifecycle.ERRORPROCESSING),
        (lifecycle.ERRORPROCESSING, lifecycle.UNCONFIGURED)]


@pytest.mark.slow
def test_rclpy_client_drives_the_managed_rclpy_nodes(
    ros_domain: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The nodes on the rclpy backend; this process is a plain rclpy client of GetState and
    ChangeState. Unconfigured at start, configured and activated by the client; the recorded
    torques are zero from one period after ``deactivate`` until ``activate``, and not zero
    before and after; a transition not available is refused and the loop goes on."""
    pytest.importorskip("rclpy", reason="rclpy is not installed (the ros extra)")
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState

    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    procs = start_loop(tmp_path)
    peer: RclpyClient
    services = {GetState: "get_state", ChangeState: "change_state"}

    def call(name: str, srv: Any, request: Any) -> Any:
        client = peer.node.create_client(srv, f"/frame/{name}/{services[srv]}")
        assert client.wait_for_service(timeout_sec=60)
        response = peer.done(client.call_async(request))
        peer.node.destroy_client(client)
        return response

    def state(name: str) -> str:
        return call(name, GetState, GetState.Request()).current_state.label

    def change(name: str, label: str) -> bool:
        return call(name, ChangeState, ChangeState.Request(
            transition=Transition(label=label))).success

    try:
        with rclpy_client("lifecycle_test_client", depth=1000) as peer:
            torques, next_torques = peer.torques, peer.next_torques
            for name in ("controller_node", "estimator_node"):
                assert state(name) == "unconfigured"
                assert not change(name, "activate")          # refused: not available yet
                assert change(name, "configure") and state(name) == "inactive"
                assert change(name, "activate") and state(name) == "active"
            before = next_torques(80)[-40:]                  # control on from t = 1 s (32 samples)
            first = len(torques) - len(before)
            assert min(map(abs, before)) > 0
            assert change("controller_node", "deactivate")
            deactivated = len(torques)
            assert state("controller_node") == "inactive"
            assert not change("controller_node", "deactivate")    # refused; the loop goes on
            next_torques(40)
            assert state("estimator_node") == "active"
            assert change("controller_node", "activate")
            activated = len(torques)
            assert state("controller_node") == "active"
            next_torques(40)
            # one block of zeros, non-zero before and after it: from the deactivate reply
            # until the activate reply, give or take the commands in flight (sent before a
            # transition, read by this client after its reply, or the reverse)
            run = torques[first:]
            zeros = [i for i, t in enumerate(run) if t == 0.0]
            start, end = zeros[0] + first, zeros[-1] + first
            assert zeros == list(range(zeros[0], zeros[-1] + 1)), "zeros in more than one block"
            assert deactivated - IN_FLIGHT <= start <= deactivated + IN_FLIGHT
            assert deactivated + 40 <= end <= activated + IN_FLIGHT
            assert min(map(abs, torques[end + 1:])) > 0 and len(torques) - end > 40
            # ``stillframe lifecycle`` on the rclpy backend (STILLFRAME_RMW=rclpy here)
            done = run_stillframe("lifecycle", "set", "controller_node", "configure")
            assert done.returncode == 1 and ("no transition configure from state active "
                                             "(available: deactivate, shutdown)") in done.stderr
            done = run_stillframe("lifecycle", "get", "estimator_node", "--json")
            assert done.returncode == 0 and json.loads(done.stdout)["state"] == "active"
    finally:
        for proc in reversed(procs):
            stop(proc)


@pytest.mark.slow
def test_lifecycle_command_on_the_dds_backend(
    ros_domain: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture
) -> None:
    """``stillframe lifecycle get|list|set`` on nodes of the ``dds`` backend, and its bad
    input: an unknown transition, an unknown node, a node that is not managed (exit 2); a
    transition not available now is refused with the reason (exit 1)."""
    monkeypatch.setenv("STILLFRAME_RMW", "dds")
    procs = start_loop(tmp_path)

    def run(*args: str) -> tuple[int, str, str]:
        code = cli.main(["lifecycle", *args])
        out, err = capsys.readouterr()
        return code, out.strip(), err

    try:
        assert run("get", "controller_node", "--timeout", "60")[:2] == (0, "unconfigured")
        code, _, err = run("set", "controller_node", "activate")
        assert code == 1 and ("no transition activate from state unconfigured "
                              "(available: configure, shutdown)") in err
        for name in ("controller_node", "estimator_node"):
            assert run("set", name, "configure")[:2] == (
                0, f"/frame/{name}: configure: unconfigured -> inactive")
            assert run("set", name, "activate")[0] == 0
        assert run("list", "controller_node")[:2] == (0, "deactivate\nshutdown")
        assert run("set", "controller_node", "deactivate")[0] == 0
        assert run("get", "/frame/controller_node")[1] == "inactive"
        code, _, err = run("set", "controller_node", "jump")
        assert code == 2 and "unknown transition 'jump'" in err
        code, _, err = run("get", "nobody_node", "--timeout", "1")
        assert code == 2 and "unknown node /frame/nobody_node" in err
        # found in the graph within 20 s however loaded the machine; the lifecycle answer it
        # never gives is then awaited for the rest of the 20 s
        code, _, err = run("get", "sim_node", "--timeout", "20")
        assert code == 2 and "/frame/sim_node is not a managed node" in err
        assert "Traceback" not in err
    finally:
        for proc in reversed(procs):
            stop(proc)
