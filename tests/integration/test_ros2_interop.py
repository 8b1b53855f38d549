"""Real ROS 2 beside the ``dds`` backend: rclpy Jazzy (Fast DDS, from PyPI) and Cyclone DDS in one
graph. The references are independent: rclpy's own graph API, rclpy's own publishers and
subscriptions, and the one-process closed loop (no middleware) for the numbers.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from stillframe.app import launcher, netns_lab
from stillframe.app.launcher import node_command
from stillframe.contract.topics import CONTRACT, FORCE_CMD
from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT
from stillframe.middleware import api, backend_choice, discovery
from stillframe.middleware.names import resolve_topic
from stillframe.middleware.qos import PROFILES, Reliability
from tests.support.middleware import child_env, run_stillframe, wait_for_line
from tests.support.netns import require_netns
from tests.support.waits import HANG_S

pytest.importorskip("rclpy", reason="real rclpy is installed by `make setup` ([ros] extra)")

SCENE = REPO_ROOT / "scenes" / "thesis_lqg.yaml"
#: 6 s of the thesis's set-up: control from 3 s, peaks over 3 s windows
SHORT = ["--set", "duration=6", "--set", "controller.start=3", "--set", "evaluation.window=3"]
STEPS = 6 * 32

#: a peer in its own process: publishes JointState on /t/js until it has sent 20 to a matched
#: subscription and they are acknowledged, or subscribes, prints how many arrived (at least 5
#: expected) and whether the publisher's node is in its graph
PEER = textwrap.dedent("""
    import sys
    from stillframe.contract import messages
    from stillframe.middleware.api import create_node, spin_until
    role = sys.argv[1]
    node = create_node("peer_" + role, namespace="/t", argv=["peer"])
    print("ready", flush=True)
    if role == "pub":
        pub = node.create_publisher("sensor_msgs/msg/JointState", "js", "default")
        print("matched", spin_until(node, lambda: pub.get_subscription_count() > 0, 40), flush=True)
        for i in range(20):
            pub.publish(messages.new("sensor_msgs/msg/JointState", name=["a"], position=[i]))
            spin_until(node, lambda: False, 0.02)
        print("acked", pub.wait_for_all_acked(20.0), flush=True)
        spin_until(node, lambda: False, 2.0)
    else:
        got = []
        node.create_subscription("sensor_msgs/msg/JointState", "js", got.append, "default")
        spin_until(node, lambda: len(got) >= 5, 40)
        print("received", len(got), flush=True)
        seen = lambda: ("peer_pub", "/t") in node.get_node_names_and_namespaces()
        print("publisher node seen", spin_until(node, seen, 10), flush=True)
        # the rest of the 20 before leaving (at most 5 s more): a Fast DDS writer that waits
        # for the acks of a Cyclone reader that has left waits out the reader's lease (10 s)
        spin_until(node, lambda: len(got) >= 20, 5)
    node.destroy_node()
""")


def one_process() -> dict:
    done = run_stillframe("closed-loop", str(SCENE), *SHORT, "--json", timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def launch(*args: str) -> dict:
    # a generous lock-step timeout: a timeout then means a lost sample, never a slow machine
    done = run_stillframe("launch", str(SCENE), *SHORT, "--json", "--lockstep-timeout", "10",
                          *args, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def bag_counts(path: Path) -> dict[str, int]:
    with AnyReader([path]) as reader:
        return {c.topic: c.msgcount for c in reader.connections}


@pytest.mark.slow
@pytest.mark.parametrize(("backends", "recorder"), [
    # Cyclone alone is also test_launch_e2e's lock-step run, so here it is the long one
    pytest.param(["--backend", "dds"], None, marks=pytest.mark.long),
    (["--backend", "rclpy"], None),
    (["--backend", "rclpy", "--backend", "sim_node=dds"], "rclpy"),
    # the mixed loop the other way round crosses the same vendor boundary on every topic, and
    # its dds recorder is the other tests' default one
    pytest.param(["--backend", "dds", "--backend", "sim_node=rclpy"], "dds",
                 marks=pytest.mark.long),
], ids=["all-dds", "all-rclpy", "sim-dds-rest-rclpy", "sim-rclpy-rest-dds"])
def test_mixed_vendor_loops_are_bit_identical_and_recorded_whole(
        backends: list[str], recorder: str | None, tmp_path: Path,
        ros_domain: int) -> None:
    """Lock-step through three processes on any mix of Cyclone and Fast DDS gives the one-process
    numbers bit for bit; a recorder on the other vendor than the simulator keeps every sample."""
    record = ["--record", str(tmp_path / "bag"), "--backend", f"recorder={recorder}"] if (
        recorder) else []
    nodes = launch(*backends, *record)
    reference = one_process()
    assert nodes["steps"] == reference["steps"] == STEPS
    assert nodes["complete"] is True
    for key in ("reduction_pct", "peak_uncontrolled", "peak_controlled", "peak_command"):
        assert nodes[key] == reference[key], key  # floats from JSON: equal to the last bit
    if recorder:
        counts = bag_counts(tmp_path / "bag")
        for spec in CONTRACT:
            if spec.name.startswith("/frame/") and spec.name != "/frame/floor3/force_cmd":
                assert counts[spec.name] == STEPS, spec.name


def test_bad_backend_or_range_is_one_line_and_starts_nothing(ros_domain: int) -> None:
    for args, env, message in [
        (["--backend", "zenoh"], {}, "unknown backend 'zenoh'"),
        (["--backend", "planner=dds"], {}, "unknown node 'planner'"),
        ([], {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LAN"}, "ROS_AUTOMATIC_DISCOVERY_RANGE='LAN'"),
    ]:
        done = subprocess.run(
            [sys.executable, "-m", "stillframe", "launch", str(SCENE), *args],
            env={**child_env(), **env}, cwd=REPO_ROOT, capture_output=True, text=True,
            timeout=60)
        assert done.returncode == 2, done.stderr
        assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1
        assert "started" not in done.stderr


def test_rclpy_backend_asked_for_where_rclpy_is_missing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(backend_choice, "has_rclpy", lambda: False)  # api re-exports its choice
    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    with pytest.raises(InputError, match="STILLFRAME_RMW=rclpy: rclpy cannot be imported"):
        api.backend_name()
    monkeypatch.setenv("STILLFRAME_RMW", "dds")
    with pytest.raises(InputError, match="--backend sim_node=rclpy: rclpy cannot be imported"):
        launcher.parse_backends(["sim_node=rclpy"])


@pytest.mark.parametrize(("env", "expected", "absent"), [
    ({}, [], ["AllowMulticast", "Peer"]),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "lab-ws;10.0.0.7"},
     ['<Peer address="lab-ws"/>', '<Peer address="10.0.0.7"/>', "<ParticipantIndex>auto"],
     ["AllowMulticast", "localhost"]),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
     ["<AllowMulticast>false", '<Peer address="localhost"/>', 'address="127.0.0.1"',
      "<MaxAutoParticipantIndex>32"], []),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_STATIC_PEERS": "lab-ws"},
     ["<AllowMulticast>false", '<Peer address="localhost"/>', '<Peer address="lab-ws"/>'],
     ["127.0.0.1"]),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF", "ROS_STATIC_PEERS": "lab-ws"},
     ["<AllowMulticast>false", "<ParticipantIndex>none", "<Tag>ros_discovery_off_"], ["Peer"]),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SYSTEM_DEFAULT", "ROS_STATIC_PEERS": "lab-ws"}, [],
     ["Peer", "AllowMulticast"]),
    ({"ROS_LOCALHOST_ONLY": "1"}, ['<Peer address="localhost"/>'], []),
])
def test_cyclone_configuration_follows_rmw_cyclonedds(
        env: dict[str, str], expected: list[str], absent: list[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The fragments rmw_cyclonedds_cpp (Jazzy) builds for each range, and the user's
    CYCLONEDDS_URI after them (Cyclone applies a comma-separated list in order)."""
    for name in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    monkeypatch.setenv("CYCLONEDDS_URI", "file:///etc/lab.xml")
    config = discovery.cyclone_config()
    assert config.endswith("file:///etc/lab.xml")
    for text in expected:
        assert text in config
    for text in absent:
        assert text not in config


def peer(backend: str, role: str, env: dict[str, str] | None = None,
         netns: str | None = None) -> subprocess.Popen:
    argv = [sys.executable, "-c", PEER, role]
    return subprocess.Popen(
        ["ip", "netns", "exec", netns, *argv] if netns else argv,
        env={**child_env(), "STILLFRAME_RMW": backend, **(env or {})}, cwd=REPO_ROOT,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def exchange(start_subscriber: Callable[[], subprocess.Popen],
             start_publisher: Callable[[], subprocess.Popen]) -> str:
    """The subscriber, then (once its participant exists) the publisher: a Cyclone and a Fast
    DDS participant created in the same instant may take the same participant index and never
    discover each other (docs/middleware.md)."""
    subscriber = start_subscriber()
    wait_for_line(subscriber, "ready")
    publisher = start_publisher()
    out, err = subscriber.communicate(timeout=90)
    publisher.communicate(timeout=90)
    assert subscriber.returncode == 0, err[-2000:]
    return out


@pytest.mark.parametrize(("pub_backend", "sub_backend"), [("dds", "rclpy"), ("rclpy", "dds")])
def test_localhost_peers_of_both_vendors_exchange_messages(
        pub_backend: str, sub_backend: str, ros_domain: int) -> None:
    out = exchange(lambda: peer(sub_backend, "sub"), lambda: peer(pub_backend, "pub"))
    assert int(out.split()[1]) >= 5, out
    assert "publisher node seen True" in out, out


@pytest.fixture
def two_hosts() -> Iterator[tuple[str, str]]:
    """Two hosts of a network lab (:mod:`stillframe.app.netns_lab`: namespaces on one bridge
    that floods multicast, a /24 no route here uses), the stand-in for two machines on one
    subnet. The lab's prefix is this process's id, so parallel test runs never share or delete
    each other's namespaces. Skipped without root or iproute2 (CI has both); a lab that cannot
    be made is an error, not a skip."""
    require_netns()
    with netns_lab.lab() as made:
        yield made.namespace(netns_lab.HOSTS["sim_node"]), made.namespace(
            netns_lab.HOSTS["estimator_node"])


@pytest.mark.parametrize(("pub_backend", "sub_backend"), [("dds", "rclpy"), ("rclpy", "dds")])
def test_default_discovery_across_hosts(
        pub_backend: str, sub_backend: str, two_hosts: tuple[str, str],
        ros_domain: int) -> None:
    """Default settings on both sides (SUBNET: multicast discovery), each peer on its own host:
    the rclpy peer and the dds-backend node discover each other and exchange messages."""
    default = {"ROS_AUTOMATIC_DISCOVERY_RANGE": ""}
    out = exchange(lambda: peer(sub_backend, "sub", default, two_hosts[1]),
                   lambda: peer(pub_backend, "pub", default, two_hosts[0]))
    assert int(out.split()[1]) >= 5, out
    assert "publisher node seen True" in out, out


LOOP_NODES = {("sim_node", "/frame"), ("estimator_node", "/frame"), ("controller_node", "/frame")}
#: who publishes each contract topic in the LQG scene (EUK variant 2's force command is absent)
PUBLISHERS = {"/clock": "sim_node", "/diagnostics": "sim_node",
              "/frame/pendulum/torque_cmd": "controller_node",
              "/frame/state_estimate": "estimator_node",
              "/frame/state_estimate/covariance": "estimator_node"}


@pytest.mark.slow
def test_rclpy_graph_api_sees_the_dds_nodes_as_the_contract_says(
        ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """rclpy's own graph API (Fast DDS) on the three dds-backend nodes: every node, topic, type
    and the reliability and durability of every endpoint, as in the topic contract."""
    procs = [subprocess.Popen(
        node_command(name, SCENE, ["duration=300"], "realtime"), env=child_env(), cwd=REPO_ROOT,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for name in
        ("controller_node", "estimator_node", "sim_node")]
    monkeypatch.setenv("STILLFRAME_RMW", "rclpy")
    node = api.create_node("graph_probe", argv=["probe"])
    expected = {resolve_topic(s.name, "/frame"): s for s in CONTRACT if s is not FORCE_CMD}
    #: the loop's readers the test checks (discovered on their own, after the writers)
    readers_expected = {"/frame/floor1/imu": "estimator_node",
                        "/frame/state_estimate": "controller_node",
                        "/frame/pendulum/torque_cmd": "sim_node"}

    def reader_names(name: str) -> set[str]:
        return {s.node_name for s in node.get_subscriptions_info_by_topic(name)}

    try:
        def complete() -> bool:
            topics = dict(node.get_topic_names_and_types())
            return all(name in topics and node.get_publishers_info_by_topic(name)
                       for name in expected) and set(
                node.get_node_names_and_namespaces()) >= LOOP_NODES and all(
                reader in reader_names(name) for name, reader in readers_expected.items())

        assert api.spin_until(node, complete, HANG_S), node.get_topic_names_and_types()
        topics = dict(node.get_topic_names_and_types())
        for name, spec in expected.items():
            assert topics[name] == [spec.type_name], name
            profile = PROFILES[spec.qos]
            publishers = node.get_publishers_info_by_topic(name)
            assert {p.node_name for p in publishers} >= {PUBLISHERS.get(name, "sim_node")}, name
            for endpoint in publishers:
                if endpoint.node_name in ("sim_node", "estimator_node", "controller_node"):
                    assert endpoint.topic_type == spec.type_name
                    assert endpoint.qos_profile.reliability == profile.reliability, name
                    assert endpoint.qos_profile.durability == profile.durability, name
        for name, reader in readers_expected.items():
            assert reader in reader_names(name), name
            # in real time the loop reads its inputs best effort (the control path too: a late
            # estimate or command is worth nothing; docs/reliability.md)
            assert {s.qos_profile.reliability for s in node.get_subscriptions_info_by_topic(name)
                    if s.node_name == reader} == {Reliability.BEST_EFFORT}, name
    finally:
        node.destroy_node()
        for proc in procs:
            proc.kill()
            proc.wait()
