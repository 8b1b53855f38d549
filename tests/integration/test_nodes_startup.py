"""The lock-step start-up check on both backends: a writer is ready for its peer only when the
named peer's subscription is matched, not when the launch's recorder or another tool alone is
(the recorder subscribes every topic at once and used to start the loop early: a lost first
sample, a lock-step timeout)."""

from __future__ import annotations

import pytest

from stillframe.middleware import api
from stillframe.middleware.qos import DEFAULT
from stillframe.node_runtime.support import RECORDER_NODE, hears_peer, reaches_peer
from tests.support.waits import HANG_S

BACKENDS = ["dds", pytest.param("rclpy", marks=pytest.mark.skipif(
    not api.has_rclpy(), reason="rclpy is not importable here"))]
TYPE = "std_msgs/msg/UInt32"


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_recorder_alone_is_not_a_peer(backend: str, ros_domain: int,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STILLFRAME_RMW", backend)
    writer = api.create_node("writer")
    nodes = [writer]
    try:
        pub = writer.create_publisher(TYPE, "/t/x", DEFAULT)
        recorder = api.create_node(RECORDER_NODE)
        nodes.append(recorder)
        recorder.create_subscription(TYPE, "/t/x", lambda _: None, DEFAULT)
        # the recorder is matched and named in the graph: a count says ready, the check not
        assert api.spin_until(writer, lambda: pub.get_subscription_count() == 1 and any(
            ep.node_name == RECORDER_NODE
            for ep in writer.get_subscriptions_info_by_topic("/t/x")), HANG_S)
        assert not reaches_peer(writer, pub, "estimator_node")
        # nor is another node: a tool subscribed beside the loop (the idle-publisher case of
        # docs/nodes.md's start-up, on the reader side)
        tool = api.create_node("topic_echo")
        nodes.append(tool)
        tool.create_subscription(TYPE, "/t/x", lambda _: None, DEFAULT)
        assert api.spin_until(writer, lambda: pub.get_subscription_count() == 2, HANG_S)
        assert not reaches_peer(writer, pub, "estimator_node")
        peer = api.create_node("estimator_node")
        nodes.append(peer)
        sub = peer.create_subscription(TYPE, "/t/x", lambda _: None, DEFAULT)
        assert api.spin_until(writer, lambda: reaches_peer(writer, pub, "estimator_node"), HANG_S)
        assert pub.get_subscription_count() == 3           # all matched when it says ready
        assert api.spin_until(peer, lambda: hears_peer(peer, sub, "/writer"), HANG_S)
        assert not hears_peer(peer, sub, "controller_node")
    finally:
        for node in nodes:
            node.destroy_node()
