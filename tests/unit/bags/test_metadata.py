"""``metadata.yaml`` checked against the storage files: each way it can say less (or more) than
the file holds is named by ``bag info`` (:func:`bag_summary`'s problems), and the metadata we
write is read the same by rosbags' own reader (another implementation of the format)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from rosbags.rosbag2 import Reader

from stillframe.bags.metadata import dump_metadata, load_metadata, parse_metadata
from stillframe.bags.storage import bag_summary
from stillframe.contract.messages import TYPESTORE
from stillframe.locations import REPO_ROOT
from stillframe.recording.recorder import MISSING_KEY

HAMMER = REPO_ROOT / "bags" / "hammer"
Edit = Callable[[dict], None]


def _topic(info: dict, i: int = 0) -> dict:
    return info["topics_with_message_count"][i]


#: an edit of the sample bag's metadata (valid types, wrong facts) and what the line must name
EDITS: dict[str, tuple[Edit, str]] = {
    "a topic's count": (lambda m: _topic(m).update(message_count=250),
                        "/frame/floor1/imu: it counts 250 messages, they hold 256"),
    "the total count": (lambda m: m.update(message_count=1000),
                        "message_count: it says 1000, they hold 1024"),
    "a topic it does not hold": (
        lambda m: _topic(m)["topic_metadata"].update(name="/frame/floor9/imu"),
        "it lists /frame/floor9/imu, which they do not hold"),
    "a topic it does not list": (lambda m: m["topics_with_message_count"].pop(),
                                 "they hold /frame/excitation/wrench, which it does not list"),
    "another type": (
        lambda m: _topic(m)["topic_metadata"].update(type="geometry_msgs/msg/WrenchStamped"),
        "it gives /frame/floor1/imu the type geometry_msgs/msg/WrenchStamped, they "
        "sensor_msgs/msg/Imu"),
    "the start": (lambda m: m["starting_time"].update(nanoseconds_since_epoch=5),
                  "it spans 5 + 7968750000 ns, the messages 0 + 7968750000 ns"),
    "the duration": (lambda m: m["duration"].update(nanoseconds=1),
                     "it spans 0 + 1 ns"),
    "the files": (lambda m: m["files"][0].update(path="other.mcap"),
                  "its files (other.mcap) are not its relative_file_paths (hammer.mcap)"),
}


@pytest.mark.parametrize("edit", sorted(EDITS))
def test_each_disagreement_with_the_files_is_named(tmp_path: Path, edit: str) -> None:
    change, named = EDITS[edit]
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "hammer.mcap").write_bytes((HAMMER / "hammer.mcap").read_bytes())
    document = yaml.safe_load((HAMMER / "metadata.yaml").read_text())
    change(document["rosbag2_bagfile_information"])
    (bag / "metadata.yaml").write_text(yaml.safe_dump(document))
    (problem,) = bag_summary(bag, TYPESTORE).problems
    assert problem.startswith(f"{bag / 'metadata.yaml'} disagrees with the storage files: ")
    assert named in problem


def test_the_sample_bag_agrees_with_its_file() -> None:
    assert bag_summary(HAMMER, TYPESTORE).problems == []


def test_what_we_write_reads_the_same_in_rosbags(tmp_path: Path) -> None:
    """The sample bag's metadata written again by :func:`dump_metadata` (with custom data, as
    the recorder adds it): parsed back equal, and rosbags' reader sees the same counts, times,
    QoS profiles and hashes (custom data: plain PyYAML, rosbags' reader does not expose it)."""
    meta = load_metadata(HAMMER)
    meta = type(meta)(**{**meta.__dict__, "custom_data": {MISSING_KEY: '{"/a": 3}'},
                         "ros_distro": "jazzy"})
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "hammer.mcap").write_bytes((HAMMER / "hammer.mcap").read_bytes())
    (bag / "metadata.yaml").write_text(dump_metadata(meta))
    plain = yaml.safe_load((bag / "metadata.yaml").read_text())
    assert parse_metadata(plain, bag / "metadata.yaml") == meta
    assert plain["rosbag2_bagfile_information"]["custom_data"] == {MISSING_KEY: '{"/a": 3}'}
    with Reader(bag) as reader:
        assert reader.message_count == meta.message_count == 1024
        assert (reader.start_time, reader.duration) == (meta.starting_time_ns,
                                                        meta.duration_ns + 1)
        assert reader.ros_distro == "jazzy"
        by_topic = {c.topic: c for c in reader.connections}
        for topic in meta.topics:
            assert by_topic[topic.name].msgcount == topic.message_count
            assert by_topic[topic.name].ext.offered_qos_profiles == topic.offered_qos
            assert by_topic[topic.name].digest == topic.type_description_hash
