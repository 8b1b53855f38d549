"""Which nodes make a second launch refuse (:mod:`stillframe.app.running_graph`), on a
hand-made graph: the loop's nodes in ``/frame``, launchers of other processes started before
this one; not later launchers, not this process's earlier launches, not other nodes."""

from __future__ import annotations

import pytest

from stillframe.app.running_graph import check, others
from stillframe.errors import InputError

LOOP = ("sim_node", "estimator_node", "controller_node", "container_node")


class Graph:
    def __init__(self, mine: str, *nodes: tuple[str, str]) -> None:
        self.mine, self.nodes = mine, [(mine, "/"), *nodes]

    def get_name(self) -> str:
        return self.mine

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        return self.nodes


def test_earlier_launchers_of_other_processes_and_loop_nodes_count() -> None:
    graph = Graph("_stillframe_launch_200_1000",
                  ("_stillframe_launch_100_999", "/"),      # another process, earlier
                  ("_stillframe_launch_300_1001", "/"),     # later: it refuses, not us
                  ("_stillframe_launch_200_500", "/"),      # this process's earlier launch
                  ("sim_node", "/frame"), ("sim_node", "/lab"), ("talker", "/"))
    assert others(graph, LOOP) == ["/_stillframe_launch_100_999", "/frame/sim_node"]
    assert others(graph, ()) == ["/_stillframe_launch_100_999"]     # the watch while running


def test_the_refusal_is_one_line_naming_the_domain_and_the_graph(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "221")
    graph = Graph("_stillframe_launch_200_1000", ("controller_node", "/frame"))
    with pytest.raises(InputError, match=r"^another stillframe loop is running on "
                       r"ROS_DOMAIN_ID=221: /frame/controller_node; stop it or launch on "
                       r"another ROS_DOMAIN_ID$"):
        check(graph, LOOP)
    check(Graph("_stillframe_launch_200_1000", ("talker", "/")), LOOP)   # nothing to refuse
