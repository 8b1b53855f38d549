"""Writer identity on an input topic (:mod:`stillframe.loop.writer_gate`), on a hand-made graph
and clock: one node's writers taken, others refused and counted by reason, restarts taken, and
the graph asked only for writers not decided yet."""

from __future__ import annotations

import unittest.mock
from types import SimpleNamespace

import pytest

from stillframe.contract import messages
from stillframe.contract.codecs import (
    CommandMessage,
    carries_token,
    stamped_frame,
    token_suffix,
)
from stillframe.contract.signals import Command
from stillframe.loop.writer_gate import (
    RECHECK_NS,
    STREAM_IDLE_NS,
    InputGates,
    WriterGate,
    graph_writers,
)

SIM, SIM2, STRAY, STRAY2 = b"a" * 16, b"b" * 16, b"s" * 16, b"t" * 16


class Graph:
    """The topic's writers, a clock, and how often the gate asked the graph."""

    def __init__(self, *writers: tuple[bytes, str]) -> None:
        self.writers = list(writers)
        self.asked = 0
        self.now = 0

    def __call__(self) -> list[tuple[bytes, str]]:
        self.asked += 1
        return list(self.writers)

    def gate(self, pinned: str = "") -> WriterGate:
        return WriterGate(pinned, self, clock=lambda: self.now)


def test_first_writer_seen_is_taken_others_refused_without_asking_again() -> None:
    graph = Graph((SIM, "/frame/sim_node"), (STRAY, "/frame/stray"))
    gate = graph.gate()
    assert gate.admits(SIM) and graph.asked == 0            # the first one: no graph needed
    assert not gate.admits(STRAY)
    asked = graph.asked
    assert all(gate.admits(SIM) for _ in range(100))            # a set lookup
    assert not any(gate.admits(STRAY) for _ in range(100))
    assert graph.asked == asked
    assert dict(gate.rejected) == {"second_writer": 101}
    report = gate.report()
    assert report["writer"] == "/frame/sim_node" and report["ignored_writers"] == "/frame/stray"


def test_a_restarted_node_is_taken_by_its_name_the_stray_still_refused() -> None:
    for pinned in ("", "sim_node"):
        graph = Graph((SIM, "/frame/sim_node"), (STRAY, "/frame/stray"))
        gate = graph.gate(pinned)
        assert gate.admits(SIM) and not gate.admits(STRAY)
        graph.writers = [(SIM, "/frame/sim_node"), (SIM2, "/frame/sim_node"),
                         (STRAY, "/frame/stray")]           # the old one not gone yet
        assert gate.admits(SIM2) and not gate.admits(STRAY), pinned
        assert dict(gate.rejected) == {"second_writer": 2}


def test_an_unnamed_writer_is_asked_about_again_after_a_while() -> None:
    graph = Graph()
    gate = graph.gate("sim_node")
    assert not gate.admits(STRAY)                           # not in the graph yet
    graph.writers = [(STRAY, "/frame/stray"), (SIM, "/"), (SIM2, "/frame/sim_node")]
    assert not gate.admits(STRAY)                           # asked a moment ago: not yet
    asked = graph.asked
    graph.now += RECHECK_NS
    assert not gate.admits(STRAY) and graph.asked == asked + 1   # named now: a second writer
    assert not gate.admits(SIM)                              # the graph has no name for it
    assert gate.admits(SIM2)
    assert dict(gate.rejected) == {"unknown_writer": 3, "second_writer": 1}
    assert gate.report()["ignored_writers"] == f"/frame/stray,{SIM.hex()}"


def test_first_seen_takes_an_unnamed_writer_once_the_one_taken_is_gone() -> None:
    graph = Graph((SIM, "/"))
    gate = graph.gate()
    assert gate.admits(SIM)                                 # first seen, not named
    graph.writers = [(SIM, "/"), (SIM2, "/")]
    assert not gate.admits(SIM2)                            # cannot tell while SIM is there
    graph.writers = [(SIM2, "/")]
    graph.now += RECHECK_NS
    assert gate.admits(SIM2)                                # SIM gone: a restart
    assert gate.taken == {SIM2}
    assert dict(gate.rejected) == {"unknown_writer": 1}


def test_without_writer_ids_only_a_single_writer_is_safe() -> None:
    graph = Graph((SIM, "/frame/sim_node"))
    gate = graph.gate()
    assert gate.admits(b"")
    graph.writers.append((STRAY, "/frame/stray"))
    assert gate.admits(b"")                                 # the count is kept for a while
    graph.now += RECHECK_NS
    assert not gate.admits(b"") and not gate.admits(b"")
    assert graph.asked == 2
    assert dict(gate.rejected) == {"ambiguous_writer": 2}


class Parameters:
    """The node side :class:`InputGates` needs: its namespace."""

    def get_namespace(self) -> str:
        return "/frame"


def test_the_graph_is_kept_read_until_a_first_writer_is_taken_then_left_alone() -> None:
    gates = InputGates(Parameters(), {"sensor_writer": ""})  # type: ignore[arg-type]
    graphs = {topic: Graph((SIM, "/frame/sim_node")) for topic in ("/a", "/b")}
    for topic, graph in graphs.items():
        gates.gates[topic] = graph.gate()
    clock = iter(range(0, 10 * RECHECK_NS, RECHECK_NS // 2))
    with unittest.mock.patch("time.monotonic_ns", lambda: next(clock)):
        for _ in range(4):                                  # 0, 0.5, 1, 1.5 recheck periods
            gates.keep_graph_read()
        assert [g.asked for g in graphs.values()] == [2, 2]     # every RECHECK_NS
        assert gates.gates["/a"].admits(SIM)
        for _ in range(6):
            gates.keep_graph_read()
    assert [g.asked for g in graphs.values()] == [2, 2]         # not once a writer is taken
    assert gates.values()["a_writer"] == "/frame/sim_node"      # named when reported


class CountingNode(Parameters):
    """A node whose graph has one writer per topic, counting how it was asked."""

    def __init__(self) -> None:
        self.counted: list[str] = []
        self.listed: list[str] = []

    def count_publishers(self, topic: str) -> int:
        self.counted.append(topic)
        return 1

    def get_publishers_info_by_topic(self, topic: str) -> list[object]:
        self.listed.append(topic)
        return [type("Endpoint", (), {"endpoint_gid": SIM, "node_namespace": "/frame",
                                      "node_name": "sim_node"})()]


def test_without_writer_ids_the_writers_are_counted_not_listed_and_the_graph_left_alone(
) -> None:
    """rclpy (Jazzy) gives no writer GIDs: the gate asks the node for the count of the topic's
    writers (a C call there), never for the endpoint list (44 µs), and a sample without a GID
    ends the graph reads before the first sample as a taken writer does."""
    node = CountingNode()
    gates = InputGates(node, {"sensor_writer": ""})  # type: ignore[arg-type]
    gate = gates.add("/a", "sensor_writer")
    clock = iter(range(0, 10 * RECHECK_NS, RECHECK_NS))
    with unittest.mock.patch("time.monotonic_ns", lambda: next(clock)):
        gates.keep_graph_read()                             # t = 0: read before any sample
        assert node.listed == ["/a"]
        gate.clock = lambda: 0
        assert gate.admits(b"") and node.counted == ["/a"]
        gate.clock = lambda: RECHECK_NS
        assert gate.admits(b"") and node.counted == ["/a", "/a"]
        for _ in range(5):
            gates.keep_graph_read()
    assert node.listed == ["/a"] and not gate.rejected


def test_without_writer_ids_an_idle_publisher_changes_nothing() -> None:
    """rclpy: no GIDs, but each writer's sequence numbers. A publisher that never writes (the
    graph shows it) costs no sample, and the graph's writer count is never asked."""
    graph = Graph((SIM, "/frame/sim_node"), (STRAY, "/frame/idle_teleop"))
    gate = graph.gate("sim_node")
    assert all(gate.admits(b"", n) for n in range(1, 1001))
    assert all(gate.admits(b"", n) for n in range(1003, 1400, 3))   # samples lost: gaps
    assert not gate.rejected and graph.asked == 1   # the first stream, named once
    assert gate.report()["writer"] == "/frame/sim_node"
    assert gate.report()["ignored_writers"] == ""


class Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def warning(self, line: str) -> None:
        self.lines.append(line)


def test_without_writer_ids_a_writing_stranger_is_refused_counted_and_named_at_once() -> None:
    graph = Graph((SIM, "/frame/sim_node"), (STRAY, "/frame/teleop"))
    gates = InputGates(Parameters(), {"command_writer": ""})  # type: ignore[arg-type]
    gate = gates.gates["/cmd"] = graph.gate("sim_node")
    assert all(gate.admits(b"", n) for n in range(1, 301))
    log = Log()
    with unittest.mock.patch("time.monotonic_ns", lambda: 0):
        assert not gates.announce(log)                  # nothing refused: nothing to say
        for n in range(1, 51):                          # the stranger from its first sample
            assert gate.admits(b"", 300 + n)            # the loop's writer goes on
            assert not gate.admits(b"", n)
        assert gates.announce(log) and not gates.announce(log)
    assert log.lines == ["/cmd: refusing the samples of another writer: /frame/teleop (50 so far)"]
    assert dict(gate.rejected) == {"second_writer": 50}
    assert gate.report()["ignored_writers"] == "/frame/teleop"


class RmwGraph:
    """A node whose graph lists the topic's writers as rmw does: a writer whose participant's node
    list has not come yet under ``_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_``."""

    def __init__(self, *writers: tuple[bytes, str, str]) -> None:
        self.writers = list(writers)

    def get_publishers_info_by_topic(self, topic: str) -> list[SimpleNamespace]:
        return [SimpleNamespace(endpoint_gid=g, node_namespace=ns, node_name=name)
                for g, ns, name in self.writers]


def test_without_writer_ids_a_stranger_rmw_has_not_named_is_named_once_it_is() -> None:
    """The rclpy writing-peer case: the first refusal comes before rmw knows the stranger's node;
    the log gives its writer's GID (never rmw's placeholder), then names it at the next refusal
    after the graph does."""
    graph = RmwGraph((SIM, "/frame", "sim_node"),
                     (STRAY, "_NODE_NAMESPACE_UNKNOWN_", "_NODE_NAME_UNKNOWN_"))
    assert graph_writers(graph, "/cmd")()[1] == (STRAY, "/")
    gates = InputGates(Parameters(), {"command_writer": ""})  # type: ignore[arg-type]
    gate = gates.gates["/cmd"] = WriterGate("sim_node", graph_writers(graph, "/cmd"),
                                            clock=lambda: 0)
    assert all(gate.admits(b"", n) for n in range(1, 101))
    log = Log()
    clock = iter(range(0, 100 * RECHECK_NS, RECHECK_NS))
    with unittest.mock.patch("time.monotonic_ns", lambda: next(clock)):
        assert not gate.admits(b"", 1) and gates.announce(log)
        graph.writers[1] = (STRAY, "/frame", "topic_pub")
        assert not gate.admits(b"", 2) and gates.announce(log)
        assert not gate.admits(b"", 3) and not gates.announce(log)    # said once
    said = "/cmd: refusing the samples of another writer: "
    assert log.lines == [said + f"{STRAY.hex()} (1 so far)", said + "/frame/topic_pub (2 so far)"]
    assert gate.report()["ignored_writers"] == "/frame/topic_pub"


def test_without_writer_ids_a_restart_is_taken_and_numbers_side_by_side_refused() -> None:
    graph = Graph((SIM, "/frame/sim_node"), (STRAY, "/frame/teleop"))
    gate = graph.gate("sim_node")
    assert all(gate.admits(b"", n) for n in range(1, 101))
    graph.writers = [(SIM2, "/frame/sim_node"), (STRAY, "/frame/teleop")]
    assert all(gate.admits(b"", n) for n in range(1, 11))   # a new writer of sim_node: taken
    assert not gate.admits(b"", 101)        # continues the old stream: no longer taken
    assert not gate.admits(b"", 5000)       # beyond MAX_GAP above any stream: a new one
    assert gate.admits(b"", 11)             # the restarted writer still taken
    graph.now += STREAM_IDLE_NS + 1         # the streams refused are idle: forgotten
    assert gate.admits(b"", 12)
    assert not any(gate.admits(b"", n) for n in range(6, 12))   # a stranger from 6 on
    assert gate.admits(b"", 13)
    assert not gate.admits(b"", 12) and not gate.admits(b"", 13)   # now as far as the loop's
    assert not gate.admits(b"", 14) and not gate.admits(b"", 14)   # as near to both: refused
    assert dict(gate.rejected) == {"second_writer": 10, "ambiguous_writer": 2}
    assert gate.report()["ignored_writers"] == "/frame/teleop"


def test_without_writer_ids_a_jump_is_taken_while_the_graph_shows_only_the_taken_node() -> None:
    graph = Graph((SIM, "/frame/sim_node"))
    gate = graph.gate()
    assert gate.admits(b"", 1) and gate.admits(b"", 2)
    assert gate.admits(b"", 2 + 10 * 256)   # a long outage: a new stream, but nobody else
    assert gate.admits(b"", 3 + 10 * 256) and not gate.rejected
    assert gate.report()["writer"] == "/frame/sim_node"


def test_without_writer_ids_a_restart_the_graph_shows_late_is_taken_after_a_recheck() -> None:
    graph = Graph((SIM, "/frame/sim_node"), (STRAY, "/frame/teleop"))
    gate = graph.gate("sim_node")
    assert all(gate.admits(b"", n) for n in range(1, 101))
    assert not gate.admits(b"", 1)          # the restarted writer, not in the graph yet
    graph.writers = [(SIM2, "/frame/sim_node"), (STRAY, "/frame/teleop")]
    asked = graph.asked
    assert not gate.admits(b"", 2) and graph.asked == asked     # refused without asking
    graph.now += RECHECK_NS
    assert gate.admits(b"", 3) and gate.admits(b"", 4)         # asked again: a restart
    assert dict(gate.rejected) == {"second_writer": 2}


def test_without_writer_ids_the_pinned_node_is_reported_once_the_graph_names_it() -> None:
    """The first stream taken before the pinned node's writer is in the graph: reported by the
    pin's name when the graph has it, never by another writer's (an idle one's) name."""
    graph = Graph((STRAY, "/frame/idle_teleop"))
    gate = graph.gate("sim_node")
    assert gate.admits(b"", 1) and gate.admits(b"", 2)
    assert gate.report()["writer"] == "/frame/sim_node"      # the pin, resolved in /frame
    graph.writers.append((SIM, "/frame/sim_node"))
    assert gate.report()["writer"] == "/frame/sim_node"
    assert gate.report()["ignored_writers"] == ""


TOKEN = "3f9a0c2e5b7d1a64"


def command(token: str, value: float = 0.5, frame: str = "pendulum") -> bytes:
    """A torque command's CDR as a loop controller with ``token`` writes it (``frame``: what a
    foreign writer might put in its frame_id instead)."""
    msg = messages.new("geometry_msgs/msg/WrenchStamped")
    msg.header.frame_id = stamped_frame(frame, token)
    msg.wrench.torque.z = value
    return bytes(messages.serialize(msg))


def test_the_token_is_read_from_the_bytes_as_rosbags_wrote_them() -> None:
    """:func:`carries_token` on CDR that rosbags serialized: the frame_id's end, nothing else
    (not a prefix, not another token, not big-endian CDR, not a cut message)."""
    suffix = token_suffix(TOKEN)
    assert carries_token(command(TOKEN), suffix)
    assert bytes(CommandMessage(0, TOKEN).cdr(Command(0.0, 0.5), 0)) == command(TOKEN)
    assert carries_token(command(TOKEN, frame="anything"), suffix)
    for refused in (command(""), command("3f9a0c2e5b7d1a6"), command(TOKEN + "0"),
                    command("", frame=TOKEN), command(TOKEN)[:20], b"", b"\0\1"):
        assert not carries_token(refused, suffix), refused
    big = messages.new("geometry_msgs/msg/WrenchStamped")
    big.header.frame_id = stamped_frame("pendulum", TOKEN)
    assert not carries_token(messages.TYPESTORE.serialize_cdr(
        big, big.__msgtype__, little_endian=False), suffix)


@pytest.mark.parametrize("with_gids", [True, False])
def test_with_the_token_a_foreign_writer_never_commands_whatever_came_first_or_its_name(
        with_gids: bool) -> None:
    """The issue's three intruders, each with many samples in flight: one writing before the
    loop's first command (first seen), one under the controller's name in the root namespace
    (the bare-name pin matched it), one mid-run; the loop's commands are all taken, every
    other sample is refused without asking the graph, and the intruders are named fully
    qualified, never as the loop's own controller."""
    gids = {"own": SIM, "rogue": STRAY, "root": STRAY2} if with_gids else dict.fromkeys(
        ("own", "rogue", "root"), b"")
    graph = Graph((gids["rogue"] or STRAY, "/rogue_tuner"),
                  (gids["root"] or STRAY2, "/controller_node"),
                  (gids["own"] or SIM, "/frame/controller_node"))
    gates = InputGates(Parameters(), {"command_writer": "controller_node"},
                       {"command_writer": "controller_node"}, TOKEN)
    gate = gates.add("/frame/pendulum/torque_cmd", "command_writer")
    gate.writers = graph
    foreign = command("")
    for n in range(1, 501):                    # the rogue first, 500 samples
        assert not gate.admits(gids["rogue"], n, foreign)
    for n in range(1, 1001):                   # then the loop, with the other two mid-run
        assert gate.admits(gids["own"], n, command(TOKEN, 1e-3 * n))
        assert not gate.admits(gids["root"], n, foreign)
        assert not gate.admits(gids["rogue"], 500 + n, command("0" * 16))   # another run's
    assert graph.asked == 0                    # refused and taken without the graph
    assert dict(gate.rejected) == {"foreign_writer": 2500}
    report = gate.report()
    assert report["writer"] == "/frame/controller_node"
    named = report["ignored_writers"]
    assert named == ("/controller_node,/rogue_tuner" if with_gids
                     else "/controller_node or /rogue_tuner")
    log = Log()
    with unittest.mock.patch("time.monotonic_ns", lambda: 0):
        assert gates.announce(log)
    assert log.lines == [f"/frame/pendulum/torque_cmd: refusing the samples of a foreign writer "
                         f"(without the run's token): {named.replace(',', ', ')} (2500 so far)"]
    assert "/frame/controller_node" not in named.split(",")


def test_with_the_token_a_second_writer_under_the_loops_own_name_is_said_so() -> None:
    """Without GIDs and with no other node in the graph, the foreign samples can only come from
    a second writer named as the loop's own node: said so, never the loop's node itself."""
    graph = Graph((SIM, "/frame/controller_node"), (STRAY, "/frame/controller_node"))
    gate = WriterGate("controller_node", graph, token=token_suffix(TOKEN))
    assert not gate.admits(b"", 1, command(""))
    assert gate.report()["ignored_writers"] == "another writer named /frame/controller_node"


def test_a_topic_without_a_header_keeps_the_rule_of_a_run_without_a_token() -> None:
    """``/clock`` has no header, so no token to carry: its gate (the controller's, with
    ``use_sim_time``) takes the first writer seen (or the pinned node), where a token gate would
    refuse every sample, the simulator's too."""
    gates = InputGates(Parameters(), {"sensor_writer": ""}, {"sensor_writer": "sim_node"}, TOKEN)
    clock = gates.add("/clock", "sensor_writer", stamped=False)
    stamped = gates.add("/frame/excitation/wrench", "sensor_writer")
    tick = messages.serialize(messages.new("rosgraph_msgs/msg/Clock"))
    assert clock.token == b"" and stamped.token == token_suffix(TOKEN)
    assert clock.admits(SIM, 0, tick) and not stamped.admits(SIM, 0, tick)


def test_with_the_token_and_no_writer_ids_an_unnamed_foreign_writer_is_given_by_its_gid() -> None:
    """rclpy gives the samples no GID, and a loaded machine's graph may not have named the
    foreign node when the last report is written: the report gives the writer's GID, which a
    launch names from its own graph; the loop's own writer, once named, is never given, even
    while the graph has lost its name again."""
    graph = Graph((SIM, "/frame/sim_node"), (STRAY, "/"))
    gate = WriterGate("", graph, clock=lambda: graph.now, token=token_suffix(TOKEN),
                      own="/frame/sim_node")
    assert gate.admits(b"", 1, command(TOKEN)) and not gate.admits(b"", 1, command(""))
    assert gate.report()["ignored_writers"] == STRAY.hex()
    graph.writers = [(SIM, "/"), (STRAY, "/")]
    assert gate.report()["ignored_writers"] == STRAY.hex()
    graph.writers = [(SIM, "/frame/sim_node"), (STRAY, "/controller_node")]
    assert gate.report()["ignored_writers"] == "/controller_node"
