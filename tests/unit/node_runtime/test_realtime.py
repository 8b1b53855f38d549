"""The real-time practices (stillframe.node_runtime.realtime) and the sleep/spin pacing: what the OS
reports after each practice, the refusal messages of an unprivileged process, the collector's
work between periods, and the waits of ``wait_until`` on a scripted clock."""

from __future__ import annotations

import gc
import json
import os
import resource
import struct
import subprocess
import sys

import pytest

from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT
from stillframe.loop.pacing import wait_until
from stillframe.node_runtime.realtime import (
    CAP_SYS_NICE,
    CPU_LATENCY_DEVICE,
    GC_LIMIT,
    GC_SLACK_NS,
    GC_YOUNG,
    PRACTICES,
    Realtime,
    RealtimeOptions,
    parse_cpus,
    parse_practices,
)

ROOT = os.geteuid() == 0


def test_practices_and_cpus_are_parsed_and_bad_ones_refused() -> None:
    assert parse_practices("all") == frozenset(PRACTICES)
    assert parse_practices(" gc, fifo ") == {"gc", "fifo"}
    assert parse_practices("") == frozenset()
    assert parse_practices("none") == frozenset()
    with pytest.raises(InputError, match=r"unknown practice.*turbo"):
        parse_practices("gc,turbo")
    assert parse_cpus([-1]) == ()
    cpu = min(os.sched_getaffinity(0))
    assert parse_cpus([cpu]) == (cpu,)
    with pytest.raises(InputError, match="rt_cpus"):
        parse_cpus([10_000])


def run_child(code: str) -> dict:
    """Run ``code`` in a fresh interpreter; it prints one JSON line."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO_ROOT, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


ENTER = """
import ctypes, json, os, threading, time
os.environ["OPENBLAS_NUM_THREADS"] = "2"     # numpy's and scipy's BLAS: two threads each
import numpy, scipy.linalg
from threadpoolctl import threadpool_info
from stillframe.node_runtime.realtime import Realtime, RealtimeOptions, permissions_line

def blas_threads():
    return sorted(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")

def named(name):   # a thread with an OS name, as Cyclone names its threads
    ctypes.CDLL(None).prctl(15, name.encode())
    time.sleep(5)

for name in ("recvUC", "tev"):
    threading.Thread(target=named, args=(name,), daemon=True).start()
time.sleep(0.2)
{before}
options = RealtimeOptions(frozenset({practices}), 42, ({cpu},))
line = permissions_line(options)
rt = Realtime(options)
rt.enter()
locked_kb = int(next(l.split()[1] for l in open("/proc/self/status") if l.startswith("VmLck:")))
threads = {{}}
for t in os.listdir("/proc/self/task"):
    name = open(f"/proc/self/task/{{t}}/comm").read().strip()
    name = "main" if int(t) == os.getpid() else name
    policy = os.sched_getscheduler(int(t)) & ~os.SCHED_RESET_ON_FORK
    threads[name] = [policy, os.sched_getparam(int(t)).sched_priority,
                     sorted(os.sched_getaffinity(int(t)))]
child = os.fork()
if child == 0:
    os._exit(0 if os.sched_getscheduler(0) == os.SCHED_OTHER else 1)
_, status = os.waitpid(child, 0)
blas = blas_threads()
rt.leave()
print(json.dumps({{"applied": rt.applied, "refused": rt.refused, "threads": threads,
    "child_other": status == 0, "fifo": os.SCHED_FIFO, "other": os.SCHED_OTHER,
    "blas": blas, "blas_after_leave": blas_threads(), "line": line, "locked_kb": locked_kb}}))
"""


@pytest.mark.skipif(not ROOT, reason="SCHED_FIFO and mlockall need root here")
def test_fifo_affinity_and_mlock_reach_every_thread_and_not_children() -> None:
    cpu = max(os.sched_getaffinity(0))
    out = run_child(ENTER.format(before="", practices='{"fifo", "affinity", "mlock"}', cpu=cpu))
    assert out["refused"] == []
    assert "memory locked (CAP_IPC_LOCK)" in out["applied"]
    fifo, other = out["fifo"], out["other"]
    threads = out["threads"]
    assert threads["main"][:2] == [fifo, 42] and threads["recvUC"][:2] == [fifo, 42]
    assert threads["tev"][:2] == [other, 0]               # housekeeping stays SCHED_OTHER
    assert all(t[2] == [cpu] for t in threads.values())     # affinity: every thread
    assert out["child_other"]                               # SCHED_RESET_ON_FORK
    # the BLAS worker threads would stay SCHED_OTHER: the BLAS runs on the calling thread
    assert out["blas"] == [1, 1] and out["blas_after_leave"] == [2, 2]
    with open("/proc/self/status") as status:               # this process is untouched
        assert "VmLck:\t       0 kB" in status.read()


def unprivileged(rtprio: tuple[int, int], memlock: tuple[int, int], keep: int = 0) -> str:
    """Child code run first: these soft and hard limits, then the user ``nobody``, as a user's
    login under limits.conf would be; with capability ``keep`` (0: none) still in effect, as
    ``setcap`` on an executable gives it."""
    caps = "" if not keep else f"""
class Header(ctypes.Structure):
    _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]
class Data(ctypes.Structure):
    _fields_ = [("effective", ctypes.c_uint32), ("permitted", ctypes.c_uint32),
                ("inheritable", ctypes.c_uint32)]
libc = ctypes.CDLL(None, use_errno=True)
libc.prctl(8, 1, 0, 0, 0)                          # PR_SET_KEEPCAPS
os.setuid(65534)
bits = (Data * 2)(Data(1 << {keep}, 1 << {keep}, 0), Data(0, 0, 0))
assert libc.capset(ctypes.byref(Header(0x20080522, 0)), bits) == 0, ctypes.get_errno()
"""
    return ("import resource\n"
            f"resource.setrlimit(resource.RLIMIT_RTPRIO, {rtprio})\n"
            f"resource.setrlimit(resource.RLIMIT_MEMLOCK, {memlock})\n"
            + (caps if keep else "os.setuid(65534)\n"))


#: this machine's hard limits, which the tests may lower but not raise
HARD_RTPRIO = resource.getrlimit(resource.RLIMIT_RTPRIO)[1]
HARD_MEMLOCK = resource.getrlimit(resource.RLIMIT_MEMLOCK)[1]


@pytest.mark.skipif(not ROOT, reason="needs root to become an unprivileged user")
def test_an_unprivileged_process_is_told_what_was_refused_and_why() -> None:
    """No rtprio, 64 KiB of soft memlock below a finite hard one, not root: the soft limit is
    raised to the hard one, nothing else is tried, each refusal says why, the one line says how
    to allow it, and the collector is held all the same."""
    cpu = max(os.sched_getaffinity(0))
    memlock = min(HARD_MEMLOCK, 8 << 20)
    out = run_child(ENTER.format(before=unprivileged((0, 0), (65536, memlock)),
                                 practices='{"fifo", "mlock", "gc", "cpu_latency"}', cpu=cpu))
    refused = out["refused"]
    assert "SCHED_FIFO not permitted: RLIMIT_RTPRIO 0 and no CAP_SYS_NICE" in refused
    assert any(r.startswith(f"memory not locked: RLIMIT_MEMLOCK {memlock >> 20} MiB, less than "
                            "2 times the ") for r in refused)
    assert f"{CPU_LATENCY_DEVICE} refused: Permission denied (errno 13) (needs root)" in refused
    assert out["applied"] == ["gc frozen and off in the loop"]
    assert out["locked_kb"] == 0
    assert out["blas"] == [2, 2]                            # no SCHED_FIFO: no need
    assert all(t[0] == out["other"] for t in out["threads"].values())
    line = out["line"]
    assert line.startswith(f"real-time practice: collector held; not permitted: memory locked "
                           f"(RLIMIT_MEMLOCK {memlock >> 20} MiB, less than 2 times the ")
    assert "SCHED_FIFO (RLIMIT_RTPRIO 0 and no CAP_SYS_NICE)" in line
    assert "@realtime - rtprio 98" in line and "@realtime - memlock unlimited" in line


@pytest.mark.skipif(not ROOT, reason="needs root to become an unprivileged user")
def test_a_user_with_cap_sys_nice_gets_sched_fifo_without_root() -> None:
    """Not root, no rtprio limit, but CAP_SYS_NICE in effect: FIFO at the priority asked, on
    the main and receive threads."""
    cpu = max(os.sched_getaffinity(0))
    out = run_child(ENTER.format(before=unprivileged((0, 0), (0, 0), keep=CAP_SYS_NICE),
                                 practices='{"fifo"}', cpu=cpu))
    assert out["refused"] == []
    assert out["applied"] == ["SCHED_FIFO 42 on 2 threads (CAP_SYS_NICE); BLAS on one thread"]
    assert out["threads"]["main"][:2] == [out["fifo"], 42]
    assert out["threads"]["recvUC"][:2] == [out["fifo"], 42]
    assert out["threads"]["tev"][:2] == [out["other"], 0]
    assert out["line"] == "real-time practice: SCHED_FIFO 42 (CAP_SYS_NICE)"


@pytest.mark.skipif(not ROOT or HARD_RTPRIO < 50,
                    reason="needs root and a hard RLIMIT_RTPRIO of 50 or more to lower from "
                           "(root without CAP_SYS_RESOURCE cannot raise it)")
@pytest.mark.parametrize(("rtprio", "priority"), [((50, 50), 42), ((30, 30), 30),
                                                  ((0, 35), 35)])
def test_a_user_with_an_rtprio_limit_gets_sched_fifo_within_it(
        rtprio: tuple[int, int], priority: int) -> None:
    """Not root, no capabilities, the rtprio limit limits.conf gives a `realtime` group: FIFO
    at the priority asked (42) or the limit if lower. A hard limit above a soft 0 is raised
    to first, as a user may."""
    cpu = max(os.sched_getaffinity(0))
    out = run_child(ENTER.format(before=unprivileged(rtprio, (0, 0)), practices='{"fifo"}',
                                 cpu=cpu))
    assert out["refused"] == []
    assert out["applied"] == [f"SCHED_FIFO {priority} on 2 threads (RLIMIT_RTPRIO {rtprio[1]}); "
                              "BLAS on one thread"]
    assert out["threads"]["main"][:2] == [out["fifo"], priority]
    assert out["line"] == f"real-time practice: SCHED_FIFO {priority} (RLIMIT_RTPRIO {rtprio[1]})"


def cpu_latency_us() -> int:
    """The kernel's aggregate of every CPU-latency request (reading the device gives it)."""
    with open(CPU_LATENCY_DEVICE, "rb") as device:
        return struct.unpack("i", device.read(4))[0]


@pytest.mark.skipif(not (ROOT and os.path.exists(CPU_LATENCY_DEVICE)),
                    reason="the PM QoS device needs root")
def test_cpu_latency_is_held_at_zero_while_entered_and_released_on_leave() -> None:
    """The kernel's own aggregate is the independent check: 0 µs while the practice holds
    it, back to what it was when the node leaves (or ends)."""
    before = cpu_latency_us()
    if before == 0:
        pytest.skip("another process holds the CPU latency at 0 already")
    rt = Realtime(RealtimeOptions(frozenset({"cpu_latency"})))
    rt.enter()
    try:
        assert rt.refused == [] and rt.applied == ["CPUs kept out of idle states (PM QoS 0 us)"]
        assert cpu_latency_us() == 0
    finally:
        rt.leave()
    assert cpu_latency_us() == before
    assert rt.cpu_latency_fd is None


def test_collector_is_off_in_the_loop_and_idle_collects_the_young_generation() -> None:
    rt = Realtime(RealtimeOptions(frozenset({"gc"})))
    rt.enter()
    try:
        assert not gc.isenabled()
        rt.idle()
        assert rt.young_collections == 0                    # nothing young yet
        garbage = []
        for _ in range(2 * GC_YOUNG):                       # reference cycles: only gc frees them
            cycle: list = []
            cycle.append(cycle)
            garbage.append(cycle)
        del garbage, cycle
        assert gc.get_count()[0] > GC_YOUNG
        rt.idle()
        assert rt.young_collections == 1 and gc.get_count()[0] < GC_YOUNG
    finally:
        rt.leave()
        gc.unfreeze()
    assert gc.isenabled()


def young_cycles(n: int) -> None:
    """``n`` young objects that only the collector can free (each refers to itself)."""
    for _ in range(n):
        cycle: list = []
        cycle.append(cycle)


def test_idle_collects_only_when_the_next_sample_leaves_time() -> None:
    """The young generation past :data:`GC_YOUNG`: with less than :data:`GC_SLACK_NS` to the
    next sample the collection is put off; with enough, or without a deadline, it runs; past
    :data:`GC_LIMIT` it runs whatever the slack."""
    rt = Realtime(RealtimeOptions())
    rt.hold_collector()
    try:
        assert not gc.isenabled() and rt.applied == ["gc frozen and off in the loop"]
        young_cycles(2 * GC_YOUNG)
        rt.idle(GC_SLACK_NS - 1)
        assert (rt.young_collections, rt.deferred_collections) == (0, 1)
        assert gc.get_count()[0] > GC_YOUNG
        rt.idle(GC_SLACK_NS)
        assert rt.young_collections == 1 and gc.get_count()[0] < GC_YOUNG
        young_cycles(2 * GC_YOUNG)
        rt.idle(None)                                       # lock-step: no deadline
        assert rt.young_collections == 2
        young_cycles(GC_LIMIT + GC_YOUNG)
        rt.idle(0)
        assert (rt.young_collections, rt.forced_collections) == (3, 1)
        assert gc.get_count()[0] < GC_YOUNG
    finally:
        rt.leave()
        gc.unfreeze()
    assert gc.isenabled()


def test_wait_until_sleeps_to_the_margin_then_polls() -> None:
    """A scripted clock: each wait(s) advances it by s plus 30 ns of call overhead."""
    clock = [0]
    waits: list[float] = []

    def wait(seconds: float) -> None:
        waits.append(seconds)
        clock[0] += round(seconds * 1e9) + 30

    wait_until(1000, lambda: clock[0], wait, spin_margin_ns=200)
    assert waits[0] == pytest.approx(800e-9)                # sleep to 200 ns before due
    assert all(w == 0.0 for w in waits[1:])                 # then poll
    assert 1000 <= clock[0] < 1000 + 30
    clock[0], waits[:] = 0, []
    wait_until(1000, lambda: clock[0], wait)                # no margin: sleep all the way
    assert waits[0] == pytest.approx(1000e-9) and len(waits) == 1
    waits[:] = []
    wait_until(500, lambda: clock[0], wait, 200)            # already past due: no wait
    assert waits == []
