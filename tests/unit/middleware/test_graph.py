"""The tools' graph: discovery settling on a fake clock, the snapshot as JSON, suggestions."""

from __future__ import annotations

from dataclasses import dataclass

from stillframe.middleware.graph import (
    UNKNOWN_NODE,
    Endpoint,
    Graph,
    Service,
    did_you_mean,
    settle,
)
from stillframe.middleware.qos import SENSOR_DATA


@dataclass
class Info:
    node_name: str


class ScriptedGraph:
    """A node whose graph grows on a script of (time, nodes, endpoint owner) steps, on a fake
    clock that each spin advances by the poll period."""

    def __init__(self, steps: list[tuple[float, int, str]]) -> None:
        self.t = 0.0
        self.steps = steps

    def now(self) -> float:
        return self.t

    def spin_once(self, timeout: float) -> None:
        self.t += timeout

    def _state(self) -> tuple[int, str]:
        seen = [(n, owner) for t, n, owner in self.steps if t <= self.t]
        return seen[-1] if seen else (1, "me")

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        return [(f"n{i}", "/") for i in range(self._state()[0])]

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        return [("/t", ["std_msgs/msg/Empty"])]

    def get_publishers_info_by_topic(self, topic: str) -> list[Info]:
        return [Info(self._state()[1])]

    def get_subscriptions_info_by_topic(self, topic: str) -> list[Info]:
        return []


def test_settle_waits_for_a_quiet_graph_not_a_fixed_time() -> None:
    # nodes arrive at 0.8 s and 1.5 s: settled 1 s after the last change, not at 1 s
    node = ScriptedGraph([(0.8, 2, "a"), (1.5, 3, "a"), (2.6, 4, "a")])
    took, settled = settle(node, quiet_s=1.0, min_s=0.0, limit_s=10.0, now=node.now)
    assert settled and 2.5 <= took < 2.6     # (the node of 2.6 s comes after a quiet second)
    # nothing changes: it still waits the announcement period, then answers
    node = ScriptedGraph([])
    took, settled = settle(node, quiet_s=1.0, min_s=3.2, limit_s=10.0, now=node.now)
    assert settled and 3.2 <= took < 3.3


def test_an_endpoint_of_an_unknown_node_is_not_settled() -> None:
    # the node list of the endpoint's participant arrives only at 4 s (a change: 1 s more)
    node = ScriptedGraph([(0.1, 2, UNKNOWN_NODE), (4.0, 2, "talker")])
    took, settled = settle(node, quiet_s=1.0, min_s=0.0, limit_s=10.0, now=node.now)
    assert settled and 5.0 <= took < 5.1
    node = ScriptedGraph([(0.1, 2, "")])
    took, settled = settle(node, quiet_s=1.0, min_s=0.0, limit_s=2.0, now=node.now)
    assert not settled and 2.0 <= took < 2.1


def test_the_snapshot_survives_json() -> None:
    graph = Graph(
        nodes=[("talker", "/ns")], topics=[("/ns/chatter", ["std_msgs/msg/String"])],
        endpoints=[Endpoint("/ns/chatter", "std_msgs/msg/String", "RIHS01_ab",
                            bytes(range(16)), SENSOR_DATA, "talker", "/ns", kind="PUBLISHER")],
        services=[Service("/ns/talker", "/ns/talker/get_parameters",
                          ("rcl_interfaces/srv/GetParameters",), True)],
        settle_s=3.4, settled=True)
    import json

    again = Graph.from_json(json.loads(json.dumps(graph.to_json())))
    assert again == graph
    assert again.endpoints[0].node == "/ns/talker"
    block = again.endpoints[0].describe().splitlines()
    assert block[5] == "GID: " + ".".join(f"{b:02x}" for b in range(16))
    assert block[8] == "  History (Depth): KEEP_LAST (5)"
    assert block[7] == "  Reliability: BEST_EFFORT"


def test_suggestions_are_the_closest_names() -> None:
    topics = ["/frame/floor1/imu", "/frame/floor2/imu", "/frame/state_truth", "/rosout"]
    assert did_you_mean("/frame/flor1/imu", topics).startswith(" (did you mean "
                                                               "/frame/floor1/imu, ")
    assert did_you_mean("/completely/else", topics) == ""
