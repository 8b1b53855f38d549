"""Samples Cyclone DDS drops as undecodable, counted.

A sample whose CDR Cyclone's receive path refuses (truncated, garbage under a valid type name,
as an rclpy peer can publish) never reaches a ``dds``-backend reader: Cyclone drops it and logs
``deserialization rt/TOPIC/TYPE failed`` on stderr. The wheel's ``libddsc`` exports no log sink
(``dds_set_log_sink`` is not in its symbol table) and its reader statistics
(``dds_create_statistics``: ``discarded_bytes``) stay 0 for these samples. So
:func:`count_deserialization_failures` taps the process's stderr (file descriptor 2): a thread
passes every byte on to the real stderr unchanged and counts each such line in :data:`DROPPED`
under its ROS topic. Cyclone drops these before any node of the process sees them, so they are
the process's, not a node's: the loop nodes add them to the samples their own subscriptions
dropped (:attr:`stillframe.middleware.interface.Node.malformed`) as ``malformed_samples`` in
``/diagnostics`` and in the simulator's result. Only node executables turn it on
(:func:`stillframe.middleware.api.node_main` on the ``dds`` backend), never a process whose
stderr others capture (pytest).
"""

from __future__ import annotations

import atexit
import contextlib
import os
import re
import threading
from collections import Counter

from stillframe import interrupts

#: Cyclone's line for a refused sample: ``... deserialization rt/frame/floor1/imu/sensor_msgs::
#: msg::dds_::Imu_ failed (for reasons unknown)``
FAILED = re.compile(rb"deserialization rt(/\S+)/[\w:]+::dds_::\w+ failed")
_tapped: list[threading.Thread] = []
#: samples per topic Cyclone refused to deserialize in this process (module docstring)
DROPPED: Counter[str] = Counter()


def _write_all(fd: int, data: bytes) -> None:
    while data:
        data = data[os.write(fd, data):]


def _pump(read: int, real: int) -> None:
    pending = b""
    with contextlib.suppress(OSError):
        while data := os.read(read, 1 << 16):
            _write_all(real, data)
            *lines, pending = (pending + data).split(b"\n")
            for line in lines:
                if found := FAILED.search(line):
                    DROPPED[found.group(1).decode(errors="replace")] += 1
    os.close(read)


def count_deserialization_failures() -> None:
    """Tap stderr once per process (module docstring); restored at exit."""
    if _tapped:
        return
    real = os.dup(2)
    read, write = os.pipe()
    os.dup2(write, 2)
    os.close(write)
    thread = threading.Thread(target=_pump, args=(read, real), name="cyclone-stderr",
                              daemon=True)
    thread.start()
    _tapped.append(thread)

    def restore() -> None:
        # the pipe's last writer gone, the thread passes on what is left and ends; the wait
        # is that long only if a child process still holds the pipe (then its output is lost)
        os.dup2(real, 2)
        thread.join(10.0)

    atexit.register(restore)
    interrupts.at_finish(restore)       # a node executable ends without atexit
