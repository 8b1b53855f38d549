"""``bench loop --record``'s completeness figures against a bag built with known losses: samples
missing before the first one held are not holes, samples missing after it are."""

from __future__ import annotations

from pathlib import Path

from stillframe.app.bench.recorder_load import completeness
from stillframe.bags.storage import BagWriter
from stillframe.contract import messages
from stillframe.contract.topics import PER_SAMPLE

RATE_HZ = 1000.0
TYPES = {"/clock": "rosgraph_msgs/msg/Clock"}


def cdr(topic: str, index: int) -> bytes:
    """A message of ``topic`` stamped at sample ``index`` (its header stamp, or /clock's time)."""
    ns = index * 1_000_000
    stamp = messages.new("builtin_interfaces/msg/Time", sec=ns // 10**9, nanosec=ns % 10**9)
    if topic == "/clock":
        return bytes(messages.serialize(messages.new("rosgraph_msgs/msg/Clock", clock=stamp)))
    return bytes(messages.serialize(messages.new("std_msgs/msg/Header", stamp=stamp,
                                                 frame_id="x")))


def test_completeness_counts_holes_only_after_the_first_sample(tmp_path: Path) -> None:
    steps = 100
    dropped = {"/frame/floor1/imu": {40, 41, 77}}   # lost while recording
    late = {"/frame/state_truth": 10}               # subscribed after 10 samples
    with BagWriter(tmp_path / "bag", messages.TYPESTORE) as bag:
        for topic in PER_SAMPLE:
            bag.add_topic(topic, TYPES.get(topic, "std_msgs/msg/Header"))
        for index in range(1, steps + 1):
            for topic in PER_SAMPLE:
                if index in dropped.get(topic, ()) or index <= late.get(topic, 0):
                    continue
                bag.write(topic, index, cdr(topic, index))
    figures = completeness(tmp_path / "bag", steps, RATE_HZ)
    assert figures["per_step_holes"] == 3
    assert figures["per_step_counts"]["/frame/floor1/imu"] == steps - 3
    assert figures["per_step_counts"]["/frame/state_truth"] == steps - 10
    assert figures["per_step_min"] == steps - 10
    assert figures["complete"] is False
    assert figures["bag_messages"] == len(PER_SAMPLE) * steps - 13
