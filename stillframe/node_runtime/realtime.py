"""Opt-in real-time practice for the loop nodes, as ros2_control applies it (docs/realtime.md).

The node parameter ``rt`` names the practices to apply (``all``, or a comma list; empty: none):

- ``mlock``: ``mlockall(MCL_CURRENT | MCL_FUTURE)``, no page faults in the loop;
- ``gc``: the objects made while setting up frozen (``gc.freeze``) and the collector off inside the
  loop; the node collects the young generations itself between periods, when the next sample
  leaves time for it (:meth:`Realtime.idle`). The loop nodes hold the collector so whether asked
  or not (:meth:`Realtime.hold_collector`): it needs no privilege and changes no number;
- ``fifo``: ``SCHED_FIFO`` at ``rt_priority`` for the main thread and the DDS receive and
  delivery threads (not inherited by child processes), a timer slack of 1 ns, and the BLAS
  libraries (numpy's and scipy's OpenBLAS, through ``threadpoolctl``) on the calling thread
  only: their worker threads stay ``SCHED_OTHER``, and a ``SCHED_FIFO`` thread that waits for
  one waits until the FIFO threads leave it a CPU (the estimator's first discretisation at a new
  time step would then wait for whole periods);
- ``affinity``: every thread pinned to the CPUs of ``rt_cpus`` (e.g. ``[1]``);
- ``spin``: sim_node sleeps until ``spin_margin_us`` before a due time and polls from there
  (:func:`stillframe.loop.pacing.wait_until`);
- ``cpu_latency``: a PM QoS request of 0 µs CPU wake-up latency (``/dev/cpu_dma_latency``, as
  cyclictest makes by default) held while the node runs: idle CPUs poll instead of halting, so a
  message wakes its reader without an idle exit (on a VM, without the host rescheduling the
  virtual CPU). It holds for the whole machine and ends when the process does.

A real-time launch applies :data:`DEFAULT_PRACTICES` unless told otherwise.

What the user may (:func:`may`), no root needed: ``SCHED_FIFO`` with ``CAP_SYS_NICE`` or up to
``RLIMIT_RTPRIO`` (the ``rtprio`` of ``/etc/security/limits.conf``; the priority asked is lowered
to it), memory locking with ``CAP_IPC_LOCK`` or an ``RLIMIT_MEMLOCK`` with room for the process to
double (a finite limit under ``MCL_FUTURE`` would otherwise fail its later allocations), the PM QoS
request with write access to its device. A process first raises its soft limits to the hard ones
(which needs no privilege). A practice it may not apply is skipped with one warning naming it and
why; the node runs on without it.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import os
import resource
import struct
from dataclasses import dataclass, field
from typing import Any

from threadpoolctl import threadpool_limits

from stillframe.errors import InputError

PRACTICES = ("mlock", "gc", "fifo", "affinity", "spin", "cpu_latency")
#: what a real-time launch applies unless ``--rt`` says otherwise (each where the user may):
#: every practice but ``affinity``, which needs CPUs named, and ``cpu_latency``, which keeps
#: every CPU of the machine polling, not only the loop's, and whose effect depends on the
#: platform: on a virtual machine whose host takes polling virtual CPUs for busy ones, it makes
#: the host stop them for milliseconds (docs/realtime.md, "The PM QoS request")
DEFAULT_PRACTICES = ("mlock", "gc", "fifo", "spin")
MCL_CURRENT, MCL_FUTURE = 1, 2
PR_SET_TIMERSLACK = 29
#: name prefixes of the threads a sample passes through: Cyclone's receive threads (``recv``,
#: ``recvUC``, ``recvMC``) and delivery queues (``dq.user``, ``dq.builtins``), Fast DDS's receive
#: threads
RECEIVE_THREADS = ("recv", "dq.", "dds.udp", "dds.shm")
#: ``rt_cpus`` default: the CPUs the process was started with
NO_PINNING = -1
#: young objects the collector may leave before :meth:`Realtime.idle` collects generation 0
GC_YOUNG = 700
#: generation-0 collections before :meth:`Realtime.idle` collects generation 1
GC_OLDER = 10
#: the least time [ns] before the next sample in which :meth:`Realtime.idle` collects: about ten
#: times what a generation-0 collection of :data:`GC_YOUNG` objects takes, so that it ends well
#: before the sample even on a loaded machine
GC_SLACK_NS = 300_000
#: young objects past which :meth:`Realtime.idle` collects even without slack (bounded memory)
GC_LIMIT = 20 * GC_YOUNG
#: the PM QoS interface for the CPUs' wake-up latency (kernel: Documentation/power/pm_qos_interface)
CPU_LATENCY_DEVICE = "/dev/cpu_dma_latency"
#: capability bits (linux/capability.h)
CAP_IPC_LOCK, CAP_SYS_NICE = 14, 23
#: a finite RLIMIT_MEMLOCK allows locking when it holds this many times the process's mapped size
MEMLOCK_ROOM = 2
#: what the docs tell a user to add to /etc/security/limits.conf (docs/realtime.md)
LIMITS_HINT = ("add yourself to a `realtime` group with `@realtime - rtprio 98` and "
               "`@realtime - memlock unlimited` in /etc/security/limits.conf (docs/realtime.md)")


def capable(bit: int) -> bool:
    """Whether this process has capability ``bit`` in its effective set."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("CapEff:"):
                return bool(int(line.split()[1], 16) >> bit & 1)
    return False


def raise_soft_limits() -> None:
    """The soft RLIMIT_RTPRIO and RLIMIT_MEMLOCK up to their hard limits (``limits.conf``'s
    ``-`` sets both; a ``hard`` line alone leaves the soft one low), which needs no privilege."""
    for limit in (resource.RLIMIT_RTPRIO, resource.RLIMIT_MEMLOCK):
        soft, hard = resource.getrlimit(limit)
        if soft != hard:
            with contextlib.suppress(ValueError, OSError):
                resource.setrlimit(limit, (hard, hard))


def _mapped_bytes() -> int:
    """This process's mapped size (VmSize)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def _mib(n: int) -> str:
    return f"{n / 2**20:.0f} MiB"


@dataclass(frozen=True)
class Permission:
    """Whether this process may apply a practice, and on what grounds (or why not)."""

    allowed: bool
    why: str


def fifo_priority(asked: int) -> int:
    """The ``SCHED_FIFO`` priority this process may take for ``asked``: ``asked`` with
    ``CAP_SYS_NICE``, else at most the soft RLIMIT_RTPRIO (0: none)."""
    return asked if capable(CAP_SYS_NICE) else min(asked, resource.getrlimit(
        resource.RLIMIT_RTPRIO)[0])


def may(practice: str) -> Permission:
    """Whether this process may apply ``practice``, from its capabilities and limits (module
    docstring); the practices that need nothing are always allowed."""
    if practice == "fifo":
        if capable(CAP_SYS_NICE):
            return Permission(True, "CAP_SYS_NICE")
        rtprio = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
        return (Permission(True, f"RLIMIT_RTPRIO {rtprio}") if rtprio > 0 else
                Permission(False, "RLIMIT_RTPRIO 0 and no CAP_SYS_NICE"))
    if practice == "mlock":
        if capable(CAP_IPC_LOCK):
            return Permission(True, "CAP_IPC_LOCK")
        limit = resource.getrlimit(resource.RLIMIT_MEMLOCK)[0]
        if limit == resource.RLIM_INFINITY:
            return Permission(True, "RLIMIT_MEMLOCK unlimited")
        mapped = _mapped_bytes()
        if limit >= MEMLOCK_ROOM * mapped:
            return Permission(True, f"RLIMIT_MEMLOCK {_mib(limit)}")
        return Permission(False, f"RLIMIT_MEMLOCK {_mib(limit)}, less than {MEMLOCK_ROOM} times "
                                 f"the {_mib(mapped)} this process maps")
    if practice == "cpu_latency":
        return (Permission(True, f"{CPU_LATENCY_DEVICE} writable")
                if os.access(CPU_LATENCY_DEVICE, os.W_OK)
                else Permission(False, f"{CPU_LATENCY_DEVICE} not writable (root)"))
    return Permission(True, "no privilege needed")


def permissions_line(options: RealtimeOptions) -> str:
    """One line: the practices of ``options`` this process (and so the nodes it starts as the
    same user) may apply and those it may not, with why and, for the latter, the fix."""
    raise_soft_limits()
    labels = {"mlock": "memory locked", "gc": "collector held", "fifo": "SCHED_FIFO",
              "affinity": "pinned", "spin": "sleep/spin", "cpu_latency": "CPUs out of idle"}
    got, not_got = [], []
    for practice in PRACTICES:
        if practice not in options.practices or (practice == "affinity" and not options.cpus):
            continue
        allowed = may(practice)
        label = labels[practice]
        if not allowed.allowed:
            not_got.append(f"{label} ({allowed.why})")
        elif practice == "fifo":
            got.append(f"{label} {fifo_priority(options.priority)} ({allowed.why})")
        else:
            got.append(label if practice in ("gc", "spin", "affinity")
                       else f"{label} ({allowed.why})")
    return ("real-time practice: " + (", ".join(got) or "nothing")
            + (f"; not permitted: {', '.join(not_got)}; to allow them, {LIMITS_HINT}"
               if not_got else ""))


@dataclass
class RealtimeOptions:
    """What ``rt``, ``rt_priority``, ``rt_cpus`` and ``spin_margin_us`` ask for."""

    practices: frozenset[str] = frozenset()
    priority: int = 80
    cpus: tuple[int, ...] = ()
    spin_margin_us: float = 200.0


def parse_practices(text: str) -> frozenset[str]:
    """``all``, ``none``, a comma list of :data:`PRACTICES`, or empty; InputError otherwise."""
    words = {w.strip() for w in text.split(",") if w.strip()}
    if words == {"all"}:
        return frozenset(PRACTICES)
    if words == {"none"}:
        return frozenset()
    unknown = words - set(PRACTICES)
    if unknown:
        raise InputError(f"parameter 'rt': unknown practice(s) {', '.join(sorted(unknown))} "
                         f"(expected 'all', 'none' or a comma list of {', '.join(PRACTICES)})")
    return frozenset(words)


def parse_cpus(values: list[int]) -> tuple[int, ...]:
    """The CPUs of ``rt_cpus`` (``[-1]``: no pinning); InputError for CPUs this process may not
    use."""
    if list(values) == [NO_PINNING]:
        return ()
    available = os.sched_getaffinity(0)
    if not values or any(not isinstance(c, int) or c not in available for c in values):
        raise InputError(f"parameter 'rt_cpus': expected CPUs of {sorted(available)} "
                         f"(or [-1]: no pinning), got {values!r}")
    return tuple(values)


def hold_cpu_latency(latency_us: int = 0) -> int:
    """Request at most ``latency_us`` of CPU wake-up latency for as long as the returned file
    descriptor stays open (the kernel drops the request when it is closed, or the process ends).
    OSError when the device is missing or not writable (it needs root)."""
    fd = os.open(CPU_LATENCY_DEVICE, os.O_WRONLY)
    try:
        os.write(fd, struct.pack("i", latency_us))
    except OSError:
        os.close(fd)
        raise
    return fd


def _threads() -> list[int]:
    """The thread ids of this process (scheduling and affinity are per thread on Linux)."""
    return [int(t) for t in os.listdir("/proc/self/task")]


def run_idle(idle: bool = True) -> bool:
    """Put every thread of this process at SCHED_IDLE (``idle`` False: back at SCHED_OTHER), and
    so the threads they start later: a policy is per thread on Linux, and imports start some
    (OpenBLAS's workers) before a process can ask. Going back may be refused (it needs
    CAP_SYS_NICE or an RLIMIT_NICE that allows the thread's niceness): False then, and the
    threads stay idle."""
    policy = os.SCHED_IDLE if idle else os.SCHED_OTHER
    for tid in _threads():
        try:
            os.sched_setscheduler(tid, policy, os.sched_param(0))
        except ProcessLookupError:      # ended meanwhile
            continue
        except PermissionError:
            return False
    return True


def run_nicer(increment: int) -> None:
    """Lower every thread of this process by ``increment`` nice levels (0..19; a process may do so
    without privilege), and so the threads they start later: ``os.nice`` changes only the calling
    thread on Linux, and imports start some (OpenBLAS's workers) before a process can ask."""
    for tid in _threads():
        with contextlib.suppress(ProcessLookupError):     # ended meanwhile
            os.setpriority(os.PRIO_PROCESS, tid,
                           min(19, os.getpriority(os.PRIO_PROCESS, tid) + increment))


def restore_scheduling(pid: int) -> bool:
    """Put every thread of process ``pid`` back at SCHED_OTHER and at this process's niceness,
    undoing :func:`run_idle` and :func:`run_nicer` there (a recorder that stepped back from the
    loop needs the CPU to close its bag once the loop has stopped). False where the kernel
    refuses: leaving SCHED_IDLE or raising a niceness needs CAP_SYS_NICE, or an RLIMIT_NICE
    that allows it."""
    nice = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except OSError:           # ended meanwhile
        return True
    restored = True
    for tid in tids:
        try:
            if os.sched_getscheduler(tid) == os.SCHED_IDLE:
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
            if os.getpriority(os.PRIO_PROCESS, tid) > nice:
                os.setpriority(os.PRIO_PROCESS, tid, nice)
        except ProcessLookupError:      # ended meanwhile
            continue
        except PermissionError:
            restored = False
    return restored


def _loop_threads() -> list[int]:
    """The main thread and the DDS threads a sample passes through (:data:`RECEIVE_THREADS`).
    Cyclone's housekeeping threads (``gc``, ``tev``) stay SCHED_OTHER: with every thread at
    SCHED_FIFO and the three nodes pinned to one CPU, the loop stopped (docs/realtime.md)."""
    main = os.getpid()
    found = []
    for tid in _threads():
        try:
            with open(f"/proc/self/task/{tid}/comm") as comm:
                name = comm.read().strip()
        except OSError:       # ended meanwhile
            continue
        if tid == main or name.startswith(RECEIVE_THREADS):
            found.append(tid)
    return found


def _errno_text(errno: int) -> str:
    return f"{os.strerror(errno)} (errno {errno})"


@dataclass
class Realtime:
    """The practices in effect in this process, and the collector's work between periods."""

    options: RealtimeOptions
    applied: list[str] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)
    gc_off: bool = False
    young_collections: int = 0
    #: collections :meth:`idle` put off for want of slack, and those it made without slack
    deferred_collections: int = 0
    forced_collections: int = 0
    cpu_latency_fd: int | None = None
    blas_limits: threadpool_limits | None = None

    @property
    def spin_margin_ns(self) -> int:
        """How long before a due time sim_node stops sleeping and polls (0: no polling)."""
        return round(self.options.spin_margin_us * 1e3) if "spin" in self.options.practices else 0

    def enter(self) -> None:
        """Apply every practice asked for (call once, after the node's entities exist, so the
        DDS threads are there to be scheduled)."""
        asked = self.options.practices
        if asked & {"fifo", "mlock"}:
            raise_soft_limits()
        if "mlock" in asked:
            self._mlock()
        if "fifo" in asked:
            self._fifo()
        if "affinity" in asked and self.options.cpus:
            self._try("affinity", lambda: [os.sched_setaffinity(tid, self.options.cpus)
                                           for tid in _threads()],
                      f"CPUs {','.join(map(str, self.options.cpus))}")
        if "gc" in asked:
            self.hold_collector()
        if "spin" in asked:
            self.applied.append(f"sleep/spin timing ({self.options.spin_margin_us:g} us)")
        if "cpu_latency" in asked:
            self._cpu_latency()

    def hold_collector(self) -> None:
        """Collect once, freeze what survives (the setup's objects, never scanned again) and
        turn the collector off: :meth:`idle` collects between samples instead."""
        if self.gc_off:
            return
        gc.collect()
        gc.freeze()
        gc.disable()
        self.gc_off = True
        self.applied.append("gc frozen and off in the loop")

    def _try(self, name: str, call: Any, done: str) -> bool:
        try:
            call()
        except OSError as exc:
            self.refused.append(f"{name} refused: {_errno_text(exc.errno or 0)}")
            return False
        self.applied.append(done)
        return True

    def _mlock(self) -> None:
        allowed = may("mlock")
        if not allowed.allowed:
            self.refused.append(f"memory not locked: {allowed.why}")
            return
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) == 0:
            self.applied.append(f"memory locked ({allowed.why})")
        else:
            self.refused.append(f"mlockall refused: {_errno_text(ctypes.get_errno())} "
                                "(needs CAP_IPC_LOCK or a larger RLIMIT_MEMLOCK)")

    def _cpu_latency(self) -> None:
        try:
            self.cpu_latency_fd = hold_cpu_latency()
        except OSError as exc:
            self.refused.append(f"{CPU_LATENCY_DEVICE} refused: {_errno_text(exc.errno or 0)} "
                                "(needs root)")
            return
        self.applied.append("CPUs kept out of idle states (PM QoS 0 us)")

    def _fifo(self) -> None:
        allowed = may("fifo")
        if not allowed.allowed:
            self.refused.append(f"SCHED_FIFO not permitted: {allowed.why}")
            return
        priority = fifo_priority(self.options.priority)
        param = os.sched_param(priority)
        threads = _loop_threads()
        try:
            for tid in threads:   # children started later do not inherit it
                os.sched_setscheduler(tid, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, param)
        except OSError as exc:
            self.refused.append(f"SCHED_FIFO refused: {_errno_text(exc.errno or 0)} (needs root "
                                "or CAP_SYS_NICE and an rtprio limit)")
            return
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_TIMERSLACK, 1, 0, 0, 0)
        self.blas_limits = threadpool_limits(limits=1, user_api="blas")
        self.applied.append(f"SCHED_FIFO {priority} on {len(threads)} threads ({allowed.why}); "
                            "BLAS on one thread")

    def leave(self) -> None:
        """Back to SCHED_OTHER and the collector on (for a process that goes on with other
        work; the nodes stay real-time to their end)."""
        if any(text.startswith("SCHED_FIFO") for text in self.applied):
            for tid in _loop_threads():
                with contextlib.suppress(OSError):   # a thread that ended meanwhile
                    os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
        if self.blas_limits is not None:
            self.blas_limits.restore_original_limits()
            self.blas_limits = None
        if self.gc_off:
            gc.enable()
            self.gc_off = False
        if self.cpu_latency_fd is not None:
            os.close(self.cpu_latency_fd)
            self.cpu_latency_fd = None

    def report(self, logger: Any) -> None:
        """One info line of what is in effect, one warning per refused practice."""
        if self.applied:
            logger.info(f"real-time: {'; '.join(self.applied)}")
        for text in self.refused:
            logger.warning(f"real-time: {text}; going on without it")

    def idle(self, slack_ns: int | None = None) -> None:
        """Between samples, with the collector held: collect the young generation once it has
        grown past :data:`GC_YOUNG` objects, the middle one every :data:`GC_OLDER` times
        (never the frozen setup objects), when ``slack_ns`` (the time left before the next
        sample is due; None: no deadline) is at least :data:`GC_SLACK_NS`, or when it has
        grown past :data:`GC_LIMIT` whatever the slack."""
        if not self.gc_off:
            return
        young = gc.get_count()[0]
        if young <= GC_YOUNG:
            return
        if slack_ns is not None and slack_ns < GC_SLACK_NS:
            if young <= GC_LIMIT:
                self.deferred_collections += 1
                return
            self.forced_collections += 1
        self.young_collections += 1
        gc.collect(1 if self.young_collections % GC_OLDER == 0 else 0)


def start_realtime(node: Any, options: RealtimeOptions, *, collector: bool = False) -> Realtime:
    """Enter the practices of ``options`` (and, with ``collector``, hold the collector whether
    asked or not: :meth:`Realtime.hold_collector`) and log what took effect."""
    rt = Realtime(options)
    rt.enter()
    if collector:
        rt.hold_collector()
    rt.report(node.get_logger())
    return rt
