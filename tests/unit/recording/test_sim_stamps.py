"""The recorder's sim-time stamps (``/clock`` worked out from arrival times, polled) against
what a callback recorder's ``now()`` under ``use_sim_time`` gives: the latest ``/clock`` that had
arrived before the message, replayed one event at a time."""

from __future__ import annotations

import random

from stillframe.contract import messages
from stillframe.recording.recorder import SimStamps


def clock_cdr(ns: int) -> bytes:
    return bytes(messages.serialize(messages.new(
        "rosgraph_msgs/msg/Clock", clock=messages.new(
            "builtin_interfaces/msg/Time", sec=ns // 1_000_000_000,
            nanosec=ns % 1_000_000_000))))


def test_stamps_equal_the_latest_clock_arrived_before_each_message() -> None:
    rng = random.Random(7)
    # arrivals on the system clock: /clock ticks 1 ms of sim time each, faster than real time
    events, sim, system = [], 0, 1_700_000_000_000_000_000
    for _ in range(2000):
        system += rng.randrange(1, 400_000)
        if rng.random() < 0.3:
            sim += 1_000_000
            events.append(("clock", system, sim))
        else:
            events.append(("message", system, None))
    # the callback recorder: one event at a time, now() is the last clock seen (0 before)
    expected, now = [], 0
    for kind, _, value in events:
        if kind == "clock":
            now = value
        else:
            expected.append(now)
    # the polled recorder: batches of events, /clock of the batch taken first
    stamps, got, at = SimStamps(), [], 0
    while at < len(events):
        batch = events[at:at + rng.randrange(1, 60)]
        at += len(batch)
        for kind, arrived, value in batch:
            if kind == "clock":
                stamps.add(clock_cdr(value), arrived)
        got += [stamps.stamp(arrived) for kind, arrived, _ in batch if kind == "message"]
        stamps.keep_last()
    assert got == expected
