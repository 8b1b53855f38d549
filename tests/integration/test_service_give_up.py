"""A service call that may give up (``call_service(..., give_up=...)``), on both backends: the
launcher waits for a managed node's ``change_state`` reply this way, so that a node killed in
the middle of a transition is reported at once, not after the call's timeout and a
``get_state`` call's (2 x 20 s before). The condition is forced: the server is a real
estimator_node, stopped with SIGSTOP once its ``get_state`` has answered, so no reply can come."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from stillframe.contract import messages
from stillframe.middleware import api
from tests.support.nodes import params_file, start_node, stop

BACKENDS = ["dds", pytest.param("rclpy", marks=pytest.mark.skipif(
    not api.has_rclpy(), reason="rclpy is not importable here"))]
PREFIX = "/frame/estimator_node"
#: the call's own timeout: far longer than the give-up
TIMEOUT_S = 60.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_call_gives_up_when_told_not_at_its_timeout(
        backend: str, ros_domain: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STILLFRAME_RMW", backend)
    server = start_node("estimator_node", params_file(tmp_path, "thesis_lqg", [],
                                                      autostart=False))
    caller = api.create_node("give_up_caller", argv=["test"])
    try:
        get_state = messages.new("lifecycle_msgs/srv/GetState_Request")
        deadline = time.monotonic() + 120
        while caller.call_service("lifecycle_msgs/srv/GetState", f"{PREFIX}/get_state",
                                  get_state, 5.0) is None:
            assert server.poll() is None and time.monotonic() < deadline, "no get_state"
        server.send_signal(signal.SIGSTOP)
        request = messages.new("lifecycle_msgs/srv/ChangeState_Request",
                               transition=messages.new("lifecycle_msgs/msg/Transition",
                                                       label="configure"))
        began = time.monotonic()
        asked: list[float] = []

        def give_up() -> bool:
            asked.append(time.monotonic() - began)
            return asked[-1] >= 1.0

        response = caller.call_service("lifecycle_msgs/srv/ChangeState",
                                       f"{PREFIX}/change_state", request, TIMEOUT_S,
                                       give_up=give_up)
        waited = time.monotonic() - began
        assert response is None
        # it ended at the first ask past 1 s: the asks are GIVE_UP_CHECK_S apart, and nothing
        # but the give-up could end the call before its 60 s
        assert asked[-1] >= 1.0 and all(a < 1.0 for a in asked[:-1]), asked
        assert waited < TIMEOUT_S / 2, waited
    finally:
        server.send_signal(signal.SIGCONT)
        caller.destroy_node()
        stop(server)
