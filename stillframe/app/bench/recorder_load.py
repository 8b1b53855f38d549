"""A recorder beside a real-time run, measured (``stillframe bench loop --record``).

:func:`recorder_process` runs ``stillframe record --all --use-sim-time`` as its own process on the
backend measured, as a user would beside ``launch``, and takes its CPU time (user + system, the
middleware's receive threads included) from the kernel when it exits (``wait4``).
:func:`completeness` counts the bag's samples of each topic the simulator publishes once a step
against the steps it ran, so a complete bag is shown by counts, not by timing.
:func:`write_limit` feeds the recorded bytes again, in the same run, through the recorder's write
path (:meth:`stillframe.bags.storage.BagWriter.writer_of`) and through a bare ``mcap`` writer
(the ``mcap`` package, no rosbag2 metadata): the second is the limit of a Python writer.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from stillframe.bags.storage import BagWriter, bag_summary, read_bag
from stillframe.contract import messages
from stillframe.contract.topics import PER_SAMPLE
from stillframe.errors import BagError

READY_LINE = "Recording to"
_STAMP = struct.Struct("<iI")   # the header stamp (/clock: its time), first after the CDR header
READY_TIMEOUT_S = 20.0
STOP_TIMEOUT_S = 20.0


@dataclass
class RecorderRun:
    """A recorder process; ``cpu_s`` once it exited."""

    bag: Path
    proc: subprocess.Popen
    lines: deque[str] = field(default_factory=lambda: deque(maxlen=50))
    #: CPU time from ready (subscribed to discovery) to exit (the bag closed)
    cpu_s: float = math.nan
    #: CPU time of its whole life, start-up included
    total_cpu_s: float = math.nan


@contextlib.contextmanager
def recorder_process(bag: Path, backend: str, args: Sequence[str] = ()) -> Iterator[RecorderRun]:
    """``stillframe record -o BAG --all --use-sim-time ARGS`` on ``backend``, ready (subscribed
    to discovery) when entered; stopped with SIGINT on exit, its CPU time taken."""
    argv = [sys.executable, "-m", "stillframe", "record", "-o", str(bag), "--all",
            "--use-sim-time", *args]
    env = dict(os.environ, STILLFRAME_RMW=backend, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(argv, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, errors="replace")
    run = RecorderRun(bag, proc)
    threading.Thread(target=lambda: run.lines.extend(line.rstrip() for line in proc.stdout),
                     daemon=True).start()
    started = time.monotonic()
    try:
        while not any(READY_LINE in line for line in run.lines):
            if proc.poll() is not None or time.monotonic() - started > READY_TIMEOUT_S:
                raise BagError(f"{bag}: the recorder did not start: "
                                       f"{' | '.join(list(run.lines)[-3:])}")
            time.sleep(0.05)
        ready_cpu_s = cpu_time_s(proc.pid)
        yield run
    finally:
        _stop(run)
    run.cpu_s -= ready_cpu_s


def cpu_time_s(pid: int) -> float:
    """User + system CPU time of a running process (``/proc/PID/stat``), its threads included."""
    fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _stop(run: RecorderRun) -> None:
    """SIGINT, then reap with ``wait4`` (SIGKILL after :data:`STOP_TIMEOUT_S`)."""
    with contextlib.suppress(ProcessLookupError):
        run.proc.send_signal(signal.SIGINT)
    deadline = time.monotonic() + STOP_TIMEOUT_S
    while True:
        pid, status, usage = os.wait4(run.proc.pid, os.WNOHANG)
        if pid:
            break
        if time.monotonic() > deadline:
            run.proc.kill()
            deadline = math.inf
        time.sleep(0.02)
    run.proc.returncode = os.waitstatus_to_exitcode(status)
    run.cpu_s = run.total_cpu_s = usage.ru_utime + usage.ru_stime


def completeness(bag: Path, steps: int, rate_hz: float) -> dict[str, Any]:
    """The bag's count of each per-step topic, the fewest of them, the messages in all, and the
    sample times missing between each topic's first and last sample in the bag (read from the
    header stamps: samples lost while recording, as against samples sent before the recorder
    subscribed)."""
    summary = bag_summary(bag, messages.TYPESTORE)
    counts = {t.name: t.count for t in summary.topics}
    per_step = {topic: counts.get(topic, 0) for topic in PER_SAMPLE}
    held: dict[str, set[int]] = {topic: set() for topic in PER_SAMPLE if per_step[topic]}
    for m in read_bag(bag, messages.TYPESTORE, topics=list(held)):
        sec, nanosec = _STAMP.unpack_from(m.data, 4)
        held[m.topic].add(round((sec + nanosec * 1e-9) * rate_hz))
    holes = sum(max(h) - min(h) + 1 - len(h) for h in held.values())
    return {"bag_messages": summary.message_count, "steps": steps,
            "per_step_counts": per_step, "per_step_min": min(per_step.values()),
            "per_step_holes": holes,
            "complete": all(n == steps for n in per_step.values())}


def write_limit(bag: Path) -> dict[str, float]:
    """Messages per CPU-second of the recorder's write path and of a bare ``mcap`` writer, fed
    the bag's messages (bytes in memory) one after the other in this process."""
    recorded = [(m.topic, m.type, m.stamp, m.data) for m in read_bag(bag, messages.TYPESTORE)]
    if not recorded:
        return {"write_path_msgs_per_s": math.nan, "mcap_msgs_per_s": math.nan}
    types = dict((topic, msgtype) for topic, msgtype, _, _ in recorded)
    with tempfile.TemporaryDirectory(prefix="stillframe-write-limit-") as tmp:
        with BagWriter(Path(tmp) / "ours", messages.TYPESTORE) as ours:
            for topic, msgtype in types.items():
                ours.add_topic(topic, msgtype)
            writers = {topic: ours.writer_of(topic) for topic in types}
            started = time.process_time()
            for topic, _, stamp, data in recorded:
                writers[topic](stamp, data)
            ours.close()
            ours_s = time.process_time() - started
        with open(Path(tmp) / "bare.mcap", "wb") as stream:
            bare = McapWriter(stream, compression=CompressionType.NONE)
            bare.start("ros2", "stillframe bench")
            channels = {topic: bare.register_channel(topic, "cdr", bare.register_schema(
                msgtype, "ros2msg", b"")) for topic, msgtype in types.items()}
            started = time.process_time()
            for topic, _, stamp, data in recorded:
                bare.add_message(channels[topic], log_time=stamp, data=data, publish_time=stamp)
            bare.finish()
            bare_s = time.process_time() - started
    return {"write_path_msgs_per_s": len(recorded) / ours_s,
            "mcap_msgs_per_s": len(recorded) / bare_s}
