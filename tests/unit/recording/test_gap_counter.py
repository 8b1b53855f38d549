"""The recorder's count of samples missing from a topic's stamp grid, against the count of the
grid's stamps absent from a stream built with known holes (a set difference, not the
counter's arithmetic); and the one phrase a launch and a recorder say of what a bag lacks."""

from __future__ import annotations

import random

from stillframe.recording.recorder import GapCounter, completeness, starts_with_stamp

PERIOD = 31_250_000     # the thesis's 32 Hz, in ns


def counted(stamps: list[int]) -> int | None:
    gaps = GapCounter()
    for stamp in stamps:
        gaps.add(stamp)
    return gaps.missing()


def test_holes_in_a_grid_are_counted_exactly() -> None:
    rng = random.Random(3)
    for _ in range(50):
        grid = [k * PERIOD for k in range(rng.randrange(10, 2000))]
        kept = [t for i, t in enumerate(grid) if i in (0, len(grid) - 1) or rng.random() > 0.3]
        holes = len(set(range(kept[0], kept[-1] + 1, PERIOD)) - set(kept))
        assert counted(kept) == holes


def test_a_period_of_a_fraction_of_a_nanosecond_is_a_grid() -> None:
    """1024 Hz: stamps rounded to the nanosecond from k / 1024 s, as the simulator makes them
    (steps of 976562 and 976563 ns); a hole of 2000 samples among them."""
    stamps = [round(k * 1e9 / 1024) for k in range(5000) if not 1000 <= k < 3000]
    assert counted(stamps) == 2000


def test_repeats_and_a_restart_are_not_holes() -> None:
    """A stamp sent twice (two writers of one sample) and a simulator that starts again at 0:
    the steps back and the repeats count nothing; the holes after the restart do."""
    first = [k * PERIOD for k in range(100)]
    again = [k * PERIOD for k in range(50) if k != 20]
    stamps = [*first[:60], first[59], *first[60:], *again]
    assert counted(stamps) == 1


def test_stamps_off_a_grid_are_not_counted() -> None:
    """A clock that jitters (a timer's wall-clock stamps): no grid, no count, never a huge
    number."""
    rng = random.Random(4)
    stamps, t = [], 1_700_000_000 * 10**9
    for _ in range(500):
        t += 1_000_000_000 + rng.randrange(-50_000, 50_000)
        stamps.append(t)
    assert counted(stamps) is None
    assert counted([5]) is None


def test_the_loop_topics_start_with_a_stamp_and_others_do_not() -> None:
    for msgtype in ("sensor_msgs/msg/Imu", "sensor_msgs/msg/JointState",
                    "geometry_msgs/msg/WrenchStamped", "rosgraph_msgs/msg/Clock",
                    "diagnostic_msgs/msg/DiagnosticArray", "rcl_interfaces/msg/Log"):
        assert starts_with_stamp(msgtype), msgtype
    for msgtype in ("std_msgs/msg/Float64", "std_msgs/msg/String", "nonexistent/msg/Type"):
        assert not starts_with_stamp(msgtype), msgtype


def test_completeness_says_missing_samples_apart_from_stalls_alone() -> None:
    """Missing samples make a bag "not complete"; a stall with nothing missing on the stamp grids
    makes it "may not be complete" (topics without a grid cannot be checked); neither: ""."""
    assert completeness({"/a": 0, "/b": 3, "/c": 2}, 1, 5.004) == (
        "is not complete: it misses 5 samples (/b 3, /c 2); the recorder stalled 1 times, the "
        "longest 5.00 s")
    assert completeness({"/a": 0}, 2, 0.571).startswith(
        "may not be complete: the recorder stalled 2 times, the longest 0.57 s; no sample is "
        "missing from the topics on a stamp grid")
    assert completeness({"/a": 0}, 0, 0.0) == ""


def test_samples_beyond_the_stamp_grids_make_a_bag_not_complete() -> None:
    """What the simulator sent outside the stamps a bag holds (a lost tail) is said apart from
    the grids' gaps; with nothing on the grids missing, a stall and a lost tail are "not
    complete", not "may not be"."""
    assert completeness({"/a": 0, "/b": 2}, 0, 0.0, lacks={"/a": 7, "/b": 0}) == (
        "is not complete: it misses 2 samples (/b 2); it lacks 7 more samples the simulator "
        "published, before the first or after the last it holds of their topics (/a 7)")
    assert completeness({"/a": 0}, 1, 11.3, lacks={"/a": 5120}) == (
        "is not complete: it lacks 5120 more samples the simulator published, before the "
        "first or after the last it holds of their topics (/a 5120); the recorder stalled 1 "
        "times, the longest 11.30 s")
    assert completeness({"/a": 0}, 0, 0.0, lacks={"/a": 0}) == ""
