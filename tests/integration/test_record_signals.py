"""Recording without loss (issue 11, item 8): ``stillframe record`` on seven reliable topics at
1 kHz, stopped by SIGINT or SIGTERM right after the publisher's last message (samples still in
flight): the bag holds every message the publisher sent, once (each topic's indices 0..N-1,
counted against the publisher's own count), and rosbags and the ``mcap`` library both read it.
Killed with SIGKILL instead, the bag has no footer; ``stillframe bag reindex`` recovers it up to
its last complete chunk: per topic distinct messages of what was sent.

A bag is in order of arrival (each message's log time is when it was received), not in order of
publication: a sample the transport dropped (a reader's socket full on a loaded machine) comes
when the reliable writer repairs it, after samples sent later, and is logged then. So the tests
compare each topic's indices as a set: a repaired sample is in the bag, later than its
neighbours."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from stillframe.bags.full_disk import RESERVE_NAME
from stillframe.contract import messages
from stillframe.contract.messages import TYPESTORE
from stillframe.locations import REPO_ROOT
from tests.support.middleware import child_env, finish, start_python, wait_for_line

TOPICS = [("/load/imu1", "sensor_msgs/msg/Imu"), ("/load/imu2", "sensor_msgs/msg/Imu"),
          ("/load/imu3", "sensor_msgs/msg/Imu"), ("/load/joints", "sensor_msgs/msg/JointState"),
          ("/load/truth", "sensor_msgs/msg/JointState"),
          ("/load/wrench", "geometry_msgs/msg/WrenchStamped"),
          ("/load/cmd", "geometry_msgs/msg/WrenchStamped")]

PUBLISHER = """
import sys, time
from stillframe.contract import messages
from stillframe.middleware import api
from stillframe.middleware.qos import QoSProfile
from tests.support.waits import HANG_S
topics = [t.split("=") for t in sys.argv[2:]]
n = int(sys.argv[1])
node = api.create_node("load_generator")
pubs = [node.create_publisher(kind, name, QoSProfile(depth=n)) for name, kind in topics]
assert api.spin_until(node, lambda: all(p.get_subscription_count() for p in pubs), HANG_S)
api.spin_until(node, lambda: False, 0.5)
msgs = [messages.new(kind) for _, kind in topics]
start = time.monotonic()
for k in range(n):
    while time.monotonic() < start + 1e-3 * k:
        pass
    for pub, msg in zip(pubs, msgs):
        msg.header.stamp = messages.time_msg(k)     # the index, to find gaps
        msg.header.frame_id = "x" * 64
        pub.publish(msg)
print("done", flush=True)
for pub in pubs:
    pub.wait_for_all_acked(30.0)
print("sent", n, flush=True)
"""


def _record(out: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "stillframe", "record", "-o", str(out),
                             *(t for t, _ in TOPICS)], env=child_env(), cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _run(tmp_path: Path, sig: int, n: int) -> tuple[Path, int, str]:
    out = tmp_path / "bag"
    recorder = _record(out)
    publisher = start_python(PUBLISHER, str(n), *(f"{t}={k}" for t, k in TOPICS))
    try:
        # read from the pipe up to "done" only: a buffered readline can take "sent N" along,
        # where communicate() (finish) no longer sees it
        wait_for_line(publisher, "done")
        recorder.send_signal(sig)
        _out, rec_err = finish(recorder, timeout=60)
    finally:
        if recorder.poll() is None:
            recorder.kill()
        pub_out, pub_err = finish(publisher, timeout=60)
    assert publisher.returncode == 0, pub_err[-2000:]
    return out, int(pub_out.split()[-1]), rec_err


def _indices(bag: Path) -> dict[str, list[int]]:
    """Each topic's header stamps as rosbags reads them."""
    found: dict[str, list[int]] = {t: [] for t, _ in TOPICS}
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            found[conn.topic].append(messages.stamp_ns(msg.header.stamp))
    return found


def _records(bag: Path) -> tuple[list[tuple[str, int, bytes]], list[tuple[str, int, bytes]]]:
    """Every message (topic, log time, bytes) as rosbags and as the mcap library (every CRC
    checked) read it, each in its own order sorted alike."""
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        by_rosbags = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    with (next(bag.glob("*.mcap"))).open("rb") as stream:
        by_mcap = [(channel.topic, message.log_time, message.data) for _, channel, message
                   in make_reader(stream, validate_crcs=True).iter_messages()]
    return sorted(by_rosbags), sorted(by_mcap)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_record_stopped_by_signal_loses_nothing(ros_domain: int, tmp_path: Path,
                                                sig: int) -> None:
    bag, sent, err = _run(tmp_path, sig, 1000)
    for topic, indices in _indices(bag).items():   # rosbags
        assert sorted(indices) == list(range(sent)), topic
    by_rosbags, by_mcap = _records(bag)             # the mcap library: the same bytes
    assert by_rosbags == by_mcap, err[-2000:]
    assert len(by_mcap) == sent * len(TOPICS)


@pytest.mark.slow
def test_killed_recorder_bag_reindexed_up_to_last_complete_chunk(ros_domain: int,
                                                                 tmp_path: Path) -> None:
    bag, sent, _err = _run(tmp_path, signal.SIGKILL, 3000)
    assert not (bag / "metadata.yaml").exists()
    assert (bag / RESERVE_NAME).exists()     # the killed recorder's room for its summary
    report = subprocess.run([sys.executable, "-m", "stillframe", "bag", "reindex", str(bag),
                             "--json"], env=child_env(), cwd=REPO_ROOT, capture_output=True,
                            text=True, check=True)
    summary = json.loads(report.stdout)
    assert summary["truncated"] is True
    found = _indices(bag)
    # chunks hold messages in arrival order: each topic recovers distinct messages that were
    # sent (a prefix of what arrived, which a repaired sample can leave out of publication order)
    for topic, indices in found.items():
        assert len(set(indices)) == len(indices) and set(indices) <= set(range(sent)), topic
    total = sum(len(v) for v in found.values())
    assert total == summary["messages"] and 0 < total < sent * len(TOPICS)
    assert (bag / f"{bag.name}.mcap.damaged").exists()
    assert not (bag / RESERVE_NAME).exists()
