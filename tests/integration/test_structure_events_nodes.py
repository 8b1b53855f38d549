"""Structure events through the nodes: in real time the simulator changes the plant at the
event's sample boundary (whatever the commands' timing), and a launch's bag holds when and what
changed on ``structure_events``, which ``bag info`` lists and ``play`` republishes byte for byte.
Lock-step against the one-process loop: tests/integration/test_nodes_lockstep.py."""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader

from stillframe.contract import topics
from stillframe.contract.messages import TYPESTORE
from stillframe.middleware.api import create_node
from stillframe.plant.frame_plant import FramePlant
from stillframe.recording.player import Player
from tests.integration.test_bags_transport import Proc
from tests.integration.test_nodes_lockstep import CHANGE
from tests.support.middleware import child_env, run_stillframe
from tests.support.nodes import run_loop
from tests.support.scenes import thesis_scene

TOPIC = "/frame/" + topics.STRUCTURE_EVENTS.name
EVENT_SAMPLE = 144      # CHANGE's event at 4.5 s, 32 Hz


def replay(scene: object, commands: np.ndarray, change_at: int) -> np.ndarray:
    """The plant's true state at each sample under the commands the simulator applied, with
    the structure changed at sample ``change_at``."""
    plant = FramePlant(scene)
    truth = []
    for k, command in enumerate(commands):
        if k == change_at:
            plant.change_structure(0)
        truth.append(plant.sample().truth)
        plant.advance(command)
    return np.array(truth)


@pytest.mark.slow
def test_in_real_time_the_plant_changes_at_the_events_sample_boundary(
        ros_domain: int, tmp_path: Path) -> None:
    """The three nodes paced by the wall clock: which command each period got depends on the
    machine, but the plant's truth is that of a plant changed at sample 144 under the commands
    the simulator recorded, to the last bit; changed one sample later, it is not."""
    result, hist = run_loop(tmp_path, "change_mass_floor2", CHANGE, mode="realtime")
    assert result["complete"] is True and result["mode"] == "realtime"
    (record,) = result["structure_events"]
    assert (record["sample"], record["applied_s"]) == (EVENT_SAMPLE, 4.5)
    scene = thesis_scene("change_mass_floor2", CHANGE)
    np.testing.assert_array_equal(hist["truth"], replay(scene, hist["command"], EVENT_SAMPLE))
    late = replay(scene, hist["command"], EVENT_SAMPLE + 1)
    assert not np.array_equal(hist["truth"][EVENT_SAMPLE + 2:], late[EVENT_SAMPLE + 2:])


def bag_messages(bag: Path, topic: str) -> list[tuple[int, bytes, object]]:
    """(log time, CDR bytes, message) of ``topic`` read with the mcap library and rosbags'
    type store, independent of stillframe's bag reader."""
    found = []
    with next(bag.glob("*.mcap")).open("rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            if channel.topic == topic:
                found.append((message.log_time, bytes(message.data),
                              TYPESTORE.deserialize_cdr(message.data, schema.name)))
    return found


@pytest.mark.slow
def test_a_launchs_bag_holds_the_event_bag_info_lists_it_and_play_republishes_it(
        ros_domain: int, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    sets = [a for o in CHANGE for a in ("--set", o)]
    done = run_stillframe("launch", "scenes/change_mass_floor2.yaml", *sets, "--record",
                          str(bag), "--json", timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout)
    (record,) = result["structure_events"]
    # the bag: one message, stamped with the event's sample, its status the result's record
    ((_, data, msg),) = bag_messages(bag, TOPIC)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (4, 500_000_000)
    (status,) = msg.status
    assert status.name == "/frame/sim_node: events[0]" and status.level == 0
    values = {kv.key: json.loads(kv.value) for kv in status.values}
    assert values == {"event": 0, "time_s": 4.5, "applied_s": 4.5, "sample": EVENT_SAMPLE,
                      "rig.floor_masses": record["changes"]["rig.floor_masses"]}
    assert "rig.floor_masses = [1.281, 1.0582" in status.message
    # bag info lists it
    info = run_stillframe("bag", "info", str(bag), "--json")
    assert info.returncode == 0, info.stderr
    listed = {t["name"]: t for t in json.loads(info.stdout)["topics"]}
    assert listed[TOPIC]["type"] == topics.STRUCTURE_EVENTS.type_name
    assert listed[TOPIC]["count"] == 1
    # play republishes it: a `stillframe record` process records what this player sends, once
    # its reader has matched the player's publisher (the condition, not a pause)
    copy = tmp_path / "copy"
    recorder = Proc(child_env(), "record", "-o", str(copy), TOPIC)
    node = create_node("structure_events_player")
    try:
        player = Player(node, bag, topics=[TOPIC])
        deadline = time.monotonic() + 120
        while player.publishers[TOPIC].get_subscription_count() < 1:
            assert time.monotonic() < deadline, "\n".join(recorder.lines)
            node.spin_once(0.1)
        player.play_once()
        assert player.finish()           # acknowledged by the recorder's reliable reader
        assert recorder.finish(signal.SIGINT) == 0, "\n".join(recorder.lines)
    finally:
        recorder.stop()
        node.destroy_node()
    with Reader(copy) as reader:
        assert [bytes(d) for c, _, d in reader.messages() if c.topic == TOPIC] == [data]
