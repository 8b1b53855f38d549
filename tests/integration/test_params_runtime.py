"""Parameters at run time: the wire format of the services, and the three loop nodes (real
processes, lock-step, ``scenes/thesis_lqg.yaml`` with control from 1 s) changed while they run.

References: a disabled controller commands exactly 0; a command limit L clips the LQG command to
exactly ±L (thesis §5.6's command peaks far above the L used); a new measurement noise gives the
stationary posterior covariance of the Kalman filter for the new R, computed here with scipy's
DARE solver on Φ = expm(A T) and checked to be a fixed point of filterpy's predict/update.
"""

from __future__ import annotations

import json
import struct
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.linalg as sla
from filterpy.kalman import KalmanFilter

from stillframe.app import cli
from stillframe.config.scene import load_scene
from stillframe.contract import messages, topics
from stillframe.control.supervisor import Controller
from stillframe.design.coordinates import design_map, physical_selector
from stillframe.loop.wiring import design_model
from stillframe.middleware import api, dds_services, dds_types
from tests.support.middleware import finish, run_stillframe, start_python, wait_for_line
from tests.support.nodes import SCENES, params_file, start_node, stop

OVERRIDES = ["duration=5000", "controller.start=1", "evaluation.window=1"]
NEW_MEASUREMENT_STD = [0.05, 0.05, 0.05, 0.05]
LIMIT = 0.01


# -- wire format --------------------------------------------------------------------------------
def test_request_header_is_cyclone_rmws() -> None:
    """rmw_cyclonedds' cdds_request_header_t (uint64 guid, int64 seq) sits between the
    encapsulation and the fields; cyclonedds' own serializer of the registered DDS type reads
    our bytes back field by field."""
    request = messages.new("rcl_interfaces/srv/GetParameters_Request", names=["enabled", "x"])
    data = dds_services.wrap(messages.serialize(request), 0x1122334455667788, -5)
    assert data[4:20] == struct.pack("<Qq", 0x1122334455667788, -5)
    struct_type = dds_types.idl_struct("rcl_interfaces/srv/GetParameters_Request", True)
    assert struct_type.__idl_typename__ == "rcl_interfaces::srv::dds_::GetParameters_Request_"
    decoded = struct_type.deserialize(data)
    assert (decoded.request_header_guid, decoded.request_header_seq) == (0x1122334455667788, -5)
    assert decoded.names == ["enabled", "x"]
    guid, seq, cdr = dds_services.unwrap(data)
    assert (guid, seq) == (0x1122334455667788, -5)
    assert messages.deserialize(cdr, "rcl_interfaces/srv/GetParameters_Request").names == [
        "enabled", "x"]
    assert dds_services.request_topic("/frame/a/get_parameters") == (
        "rq/frame/a/get_parametersRequest")
    assert dds_services.reply_topic("/frame/a/get_parameters") == "rr/frame/a/get_parametersReply"


def test_service_types_are_ros_jazzys() -> None:
    """The registered request/response types hash like the rcl_interfaces package's own type
    descriptions (REP 2011), where that package is installed (the ``ros`` extra)."""
    json_dir = Path(sys.prefix) / "share" / "rcl_interfaces" / "srv"   # the wheels install here
    if not json_dir.is_dir():
        pytest.skip("rcl_interfaces is not installed (the ros extra)")
    for name in ("ListParameters", "GetParameters", "SetParameters", "DescribeParameters"):
        hashes = {h["type_name"]: h["hash_string"] for h in
                  json.loads((json_dir / f"{name}.json").read_text())["type_hashes"]}
        for part in ("Request", "Response"):
            full = f"rcl_interfaces/srv/{name}_{part}"
            assert messages.type_hash(full) == hashes[full]


def test_supervisor_enable_and_limit() -> None:
    controller = Controller(lambda z, f: (0.3, False), actuator=0, period=0.1)
    estimate = type("E", (), {"t": 0.0, "z": np.zeros(8)})()
    assert controller.command(0.0, estimate, 0.0).torque == 0.3
    controller.set_limit(LIMIT)
    assert controller.command(0.0, None, 0.0).torque == LIMIT
    controller.enabled = False
    assert controller.command(0.0, None, 0.0).torque == 0.0


# -- the running loop ---------------------------------------------------------------------------
def stationary_posterior(measurement_std: list[float]) -> np.ndarray:
    """The physical 8×8 covariance the steady-state filter publishes after a full update."""
    scene = load_scene(SCENES / "thesis_lqg.yaml", OVERRIDES)
    model = design_model(scene)
    A, _ = model.linearized().state_space()
    n = model.n_dof
    C = np.vstack([A[[n + i for i in model.floor_index]], np.eye(2 * n)[model.phi_index]])
    Phi = sla.expm(A / scene.sensors.rate_hz)
    T = design_map(model)
    Q = T @ np.diag(np.square(scene.estimator.process_noise_std)) @ T.T
    R = np.diag(np.square(measurement_std))
    prior = sla.solve_discrete_are(Phi.T, C.T, Q, R)
    kf = KalmanFilter(dim_x=2 * n, dim_z=4)
    kf.F, kf.H, kf.Q, kf.R, kf.P = Phi, C, Q, R, prior
    kf.update(np.zeros(4))
    posterior = kf.P.copy()
    kf.predict()
    np.testing.assert_allclose(kf.P, prior, rtol=1e-8, atol=1e-14)   # a fixed point
    S = physical_selector(model)
    return S @ posterior @ S.T


class Watcher:
    """The test's own node: torque commands and covariances of the running loop."""

    def __init__(self) -> None:
        self.node = api.create_node("param_test_watcher", argv=["test"])
        self.torques: list[float] = []
        self.covariances: list[np.ndarray] = []
        self.node.create_subscription(
            topics.TORQUE_CMD.type_name, f"/frame/{topics.TORQUE_CMD.name}",
            lambda m: self.torques.append(float(m.wrench.torque.z)), topics.TORQUE_CMD.qos)
        self.node.create_subscription(
            topics.STATE_COVARIANCE.type_name, f"/frame/{topics.STATE_COVARIANCE.name}",
            lambda m: self.covariances.append(np.array(m.data).reshape(8, 8)), "default")
        self.lock = threading.Lock()
        self.running = True
        self.thread = threading.Thread(target=self.spin)
        self.thread.start()

    def spin(self) -> None:
        while self.running:
            self.node.spin_once(0.05)

    def next_torques(self, count: int, timeout: float = 60) -> list[float]:
        """The next ``count`` commands published from now on."""
        start = len(self.torques)
        assert wait_until(lambda: len(self.torques) >= start + count, timeout), (
            f"only {len(self.torques) - start} commands in {timeout} s")
        return self.torques[start:start + count]

    def close(self) -> None:
        self.running = False
        self.thread.join()
        self.node.destroy_node()


def wait_until(condition: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.05)
    return condition()


def start_loop(tmp_path: Path) -> list[Any]:
    params = params_file(tmp_path, "thesis_lqg", OVERRIDES,
                         result_file=str(tmp_path / "result.json"))
    return [start_node(name, params) for name in ("estimator_node", "controller_node", "sim_node")]


def param(*args: str, capsys: pytest.CaptureFixture) -> tuple[int, str, str]:
    code = cli.main(["param", *args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
def test_param_command_changes_the_running_dds_loop(
    ros_domain: int, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    procs = start_loop(tmp_path)
    watcher = Watcher()
    try:
        assert max(map(abs, watcher.next_torques(60))) > 10 * LIMIT   # control is on
        code, out, _ = param("list", "controller_node", "--json", capsys=capsys)
        listed = {p["name"]: p for p in json.loads(out)}
        assert code == 0 and listed["enabled"]["value"] is True
        assert listed["command_limit"]["value"] == 0.0 and not listed["command_limit"]["read_only"]
        assert listed["scene"]["read_only"]
        code, out, _ = param("get", "/frame/estimator_node", "measurement_noise_std",
                             capsys=capsys)
        assert code == 0 and json.loads(out) == [1e-3] * 4

        done = run_stillframe("param", "set", "controller_node", "enabled", "false")
        assert done.returncode == 0, done.stderr
        assert watcher.next_torques(40)[-30:] == [0.0] * 30   # a few were in flight

        assert param("set", "controller_node", "command_limit", "0.01", capsys=capsys)[0] == 0
        assert param("set", "controller_node", "enabled", "true", capsys=capsys)[0] == 0
        limited = np.abs(watcher.next_torques(60)[-40:])
        assert limited.max() == LIMIT and np.count_nonzero(limited == LIMIT) >= 5

        for name, value, reason in (
            # the descriptor's range, held by the middleware before the node's own check
            ("command_limit", "-1", "out of range [0, inf]"),
            ("command_limit", ".nan", "out of range"),
            ("command_limit", "abc", "wrong parameter type"), ("scene", "x.yaml", "read-only"),
            ("enabled", "1", "wrong parameter type"),
        ):
            code, _, err = param("set", "controller_node", name, value, capsys=capsys)
            assert code == 1 and reason in err, err
        code, _, err = param("set", "controller_node", "gain", "1.0", capsys=capsys)
        assert code == 2 and "has no parameter 'gain' (its parameters: autostart," in err
        code, _, err = param("set", "estimator_node", "measurement_noise_std", "[1, 1]",
                             capsys=capsys)
        assert code == 1 and "expected 4 values" in err
        code, _, err = param("set", "sim_node", "use_sim_time", "true", capsys=capsys)
        assert code == 1 and "read-only" in err
        assert np.abs(watcher.next_torques(20)).max() == LIMIT   # still running, still limited

        old = stationary_posterior([1e-3] * 4)
        # the node (FOH expm, prior − K C prior) and the test (expm, Joseph update) differ by
        # about u·cond(DARE)·‖P‖ normwise; P's entries span six decades, so the floor is ‖P‖'s
        np.testing.assert_allclose(watcher.covariances[-1], old, rtol=1e-6,
                                   atol=1e-9 * np.abs(old).max())
        code, _, _ = param("set", "estimator_node", "measurement_noise_std",
                           json.dumps(NEW_MEASUREMENT_STD), capsys=capsys)
        assert code == 0
        start = len(watcher.covariances)
        watcher.next_torques(40)
        new = stationary_posterior(NEW_MEASUREMENT_STD)
        assert not np.allclose(new, old, rtol=1e-3)
        assert len(watcher.covariances) >= start + 30
        for cov in watcher.covariances[start + 10:]:
            np.testing.assert_allclose(cov, new, rtol=1e-6, atol=1e-9 * np.abs(new).max())
    finally:
        watcher.close()
        for proc in procs:
            stop(proc)


def test_param_command_bad_input(ros_domain: int) -> None:
    for args, text in ((["get", "bad name!", "x"], "node name"),
                       (["set", "controller_node", "limit", "[1, a: 2]"], "VALUE of limit"),
                       (["get", "/nobody_here", "x", "--timeout", "0.5"], "no answer")):
        done = run_stillframe("param", *args)
        assert done.returncode == 2 and text in done.stderr, done.stderr
        assert "Traceback" not in done.stderr


@pytest.mark.slow
def test_rclpy_client_sets_parameters_of_rclpy_nodes(
    ros_domain: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The nodes on the rclpy backend; this process is a plain rclpy client of the standard
    parameter services (rclpy's AsyncParameterClient), the command is read with rclpy too."""
    rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (the ros extra)")
    from geometry_msgs.msg import WrenchStamped
    from rcl_interfaces.msg import ParameterType
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from std_msgs.msg import Float64MultiArray

    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    procs = start_loop(tmp_path)
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("param_test_client", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    torques: list[float] = []
    covariances: list[np.ndarray] = []
    node.create_subscription(WrenchStamped, "/frame/pendulum/torque_cmd",
                             lambda m: torques.append(m.wrench.torque.z), 10)
    node.create_subscription(Float64MultiArray, "/frame/state_estimate/covariance",
                             lambda m: covariances.append(np.reshape(m.data, (8, 8))), 10)

    def next_torques(count: int) -> list[float]:
        start = len(torques)
        deadline = time.monotonic() + 60
        while len(torques) < start + count and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert len(torques) >= start + count, f"only {len(torques) - start} commands"
        return torques[start:start + count]

    def done(future: Any) -> Any:
        executor.spin_until_future_complete(future, timeout_sec=30)
        assert future.done()
        return future.result()

    try:
        controller = AsyncParameterClient(node, "/frame/controller_node")
        estimator = AsyncParameterClient(node, "/frame/estimator_node")
        assert controller.wait_for_services(timeout_sec=60)
        assert estimator.wait_for_services(timeout_sec=60)
        names = done(controller.list_parameters()).result.names
        assert {"scene", "enabled", "command_limit", "use_sim_time"} <= set(names)
        values = done(estimator.get_parameters(["measurement_noise_std", "mode"])).values
        assert values[0].type == ParameterType.PARAMETER_DOUBLE_ARRAY
        assert list(values[0].double_array_value) == [1e-3] * 4
        assert values[1].string_value == "lockstep"
        assert max(map(abs, next_torques(60))) > 10 * LIMIT

        results = done(controller.set_parameters([Parameter("enabled", value=False)])).results
        assert results[0].successful
        assert next_torques(40)[-30:] == [0.0] * 30
        results = done(controller.set_parameters([
            Parameter("command_limit", value=LIMIT), Parameter("enabled", value=True)])).results
        assert all(r.successful for r in results)
        limited = np.abs(next_torques(60)[-40:])
        assert limited.max() == LIMIT and np.count_nonzero(limited == LIMIT) >= 5

        refused = done(controller.set_parameters([
            Parameter("command_limit", value=-1.0), Parameter("command_limit", value="a"),
            Parameter("scene", value="x.yaml"), Parameter("use_sim_time", value=True),
            Parameter("command_limit", value=float("nan")), Parameter("gain", value=1.0)])).results
        assert [r.successful for r in refused] == [False] * 6
        # rclpy holds a set to the descriptor's range, in its words, before the node's check
        assert "out of range" in refused[0].reason and "type" in refused[1].reason
        assert "read-only" in refused[2].reason
        assert "cannot change while the node runs" in refused[3].reason
        assert "out of range" in refused[4].reason and "undeclared" in refused[5].reason
        refused = done(estimator.set_parameters([
            Parameter("process_noise_std", value=[-1.0] * 8)])).results
        assert not refused[0].successful and "must be >= 0" in refused[0].reason
        assert np.abs(next_torques(20)).max() == LIMIT   # still running, still limited
        accepted = done(estimator.set_parameters([
            Parameter("measurement_noise_std", value=NEW_MEASUREMENT_STD)])).results
        assert accepted[0].successful
        values = done(estimator.get_parameters(["measurement_noise_std"])).values
        assert list(values[0].double_array_value) == NEW_MEASUREMENT_STD
        start = len(covariances)
        next_torques(40)
        assert len(covariances) >= start + 30
        new = stationary_posterior(NEW_MEASUREMENT_STD)
        for cov in covariances[start + 10:]:   # atol: as in the DDS test above
            np.testing.assert_allclose(cov, new, rtol=1e-6, atol=1e-9 * np.abs(new).max())

        cli_get = run_stillframe("param", "get", "controller_node", "command_limit")
        assert cli_get.returncode == 0 and float(cli_get.stdout) == LIMIT, cli_get.stderr
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        for proc in procs:
            stop(proc)


FAST_DDS_CLIENT = """\
import sys, rclpy
from rcl_interfaces.srv import GetParameters
rclpy.init()
node = rclpy.create_node("fast_dds_client")
client = node.create_client(GetParameters, "/vendor_check/get_parameters")
print("ready", client.wait_for_service(timeout_sec=30), flush=True)
future = client.call_async(GetParameters.Request(names=["limit"]))
rclpy.spin_until_future_complete(node, future, timeout_sec=3)
print("answered", future.done(), flush=True)
"""


@pytest.mark.slow
def test_services_do_not_cross_vendors(ros_domain: int) -> None:
    """What docs/middleware.md reports: a Fast DDS (rclpy) client finds the dds backend's
    parameter service and matches it, but its request, which lacks Cyclone rmw's in-payload
    header, does not fit the DDS type and never reaches the service; no answer."""
    pytest.importorskip("rclpy", reason="rclpy is not installed (the ros extra)")
    node = api.create_node("vendor_check", argv=["test"])
    node.declare_parameter("limit", 2.5)
    service = next(s for s in node._services if s.service_name.endswith("/get_parameters"))
    taken: list[bytes] = []
    take = service.take
    service.take = lambda: [*(taken.append(d) or (d, i) for d, i in take())]
    stop_spinning = threading.Event()

    def spin() -> None:
        while not stop_spinning.is_set():
            node.spin_once(0.05)

    spinner = threading.Thread(target=spin)
    spinner.start()
    try:
        out, err = finish(start_python(FAST_DDS_CLIENT), timeout=60)
    finally:
        stop_spinning.set()
        spinner.join()
        node.destroy_node()
    assert out.splitlines() == ["ready True", "answered False"], err
    assert taken == [] and service.rejected == 0


#: an rclpy (Fast DDS) node serving its parameter services for SERVE_S seconds, then exiting
FAST_DDS_SERVER = """\
import time, rclpy
rclpy.init()
node = rclpy.create_node("fast_dds_server")
node.declare_parameter("limit", 2.5)
print("serving", flush=True)
deadline = time.monotonic() + float(__import__("sys").argv[1])
while time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
node.destroy_node()
print("done", flush=True)
"""
SERVE_S = 10.0


@pytest.mark.slow
def test_dds_client_never_sends_to_a_fast_dds_service(ros_domain: int) -> None:
    """The reverse: the dds backend's client matches an rclpy (Fast DDS) parameter service's
    request reader, but that reader carries no ``serviceid`` (not rmw_cyclonedds' request
    format), so the service is never ready and nothing is sent. Sending would hurt the server:
    Fast DDS reads the in-payload header as the request's fields, fails to create an array or,
    with a sequence length of millions from the header's bytes, stalls initialising it. The
    server still spins and exits on time, with nothing in its log."""
    pytest.importorskip("rclpy", reason="rclpy is not installed (the ros extra)")
    server = start_python(FAST_DDS_SERVER, str(SERVE_S))
    node = api.create_node("vendor_check_client", argv=["test"])
    try:
        wait_for_line(server, "serving")
        client = node.create_client("rcl_interfaces/srv/GetParameters",
                                    "/fast_dds_server/get_parameters")
        request = messages.new("rcl_interfaces/srv/GetParameters_Request", names=["limit"])
        assert node.call_service("rcl_interfaces/srv/GetParameters",
                                 "/fast_dds_server/get_parameters", request, 3.0) is None
        assert client.writer.get_matched_subscriptions(), "the request reader never matched"
        assert not client.service_is_ready()
        assert client.seq == 0
    finally:
        node.destroy_node()
        out, err = finish(server, timeout=SERVE_S + 60)
    assert out.splitlines() == ["done"], err
    assert server.returncode == 0 and "failed" not in err, err
