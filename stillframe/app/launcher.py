"""Start the closed loop as separate OS processes over DDS and watch it (``stillframe launch``).

The three nodes (``sim_node``, ``estimator_node``, ``controller_node``) and optionally a bag
recorder run as children, each in its own process group (a Ctrl-C in the terminal reaches only
the launcher, which forwards one SIGINT to each child) and, on Linux, with a parent-death signal
(SIGTERM) so that no child outlives a killed launcher. The launcher keeps a hidden node on the
same ROS domain that listens to ``/diagnostics`` for the status line. The run ends when
sim_node exits after writing its result file (the scene's duration has passed); a child that
exits before that, or with a failure code, ends the run with :class:`NodeDiedError` naming it,
after the others were stopped (SIGINT first) and what they wrote was kept: the error carries a
partial result marked ``"complete": false``, also written to the result file.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from stillframe.app import running_graph
from stillframe.app.tracking import TRACKER, TRACKER_STOP_S, read_tracked, tracker_command
from stillframe.bags.metadata import load_metadata
from stillframe.config import environment
from stillframe.config.scene import Scene, load_scene
from stillframe.contract import messages
from stillframe.contract.run_token import new_run_token
from stillframe.contract.topics import DEFAULT_NAMESPACE, PER_SAMPLE, STATUS_KEYS
from stillframe.errors import BY_EXIT_CODE, BagError, InputError, StillframeError
from stillframe.fidelity.auto_model import resolve_model
from stillframe.files import write_text
from stillframe.identification.tracker import EXIT_GIVEN_UP, TRACKER_READY
from stillframe.locations import REPO_ROOT
from stillframe.loop.parts import check_loop
from stillframe.loop.spec import MODES
from stillframe.middleware import api, discovery, names
from stillframe.middleware.graph import UNNAMED_NODES, fqn
from stillframe.node_runtime.declarations import NODE_PARAMETERS, ManagedParameterValues
from stillframe.node_runtime.realtime import (
    DEFAULT_PRACTICES,
    RealtimeOptions,
    parse_practices,
    permissions_line,
    restore_scheduling,
)
from stillframe.recording.recorder import MISSING_KEY, STALLS_KEY

NODES: tuple[str, ...] = tuple(NODE_PARAMETERS)
#: the process that hosts the estimator and the controller with ``--compose``
CONTAINER = "container_node"
#: what ``--compose`` may put in the container: nothing, the estimator and controller, all
COMPOSE = ("", "pair", "all")
#: the loop's node processes that take real-time parameters besides the simulator's
LOOP = ("estimator_node", "controller_node")
#: the children whose middleware backend ``--backend NAME=BACKEND`` can choose
BACKEND_TARGETS: tuple[str, ...] = (*NODES, "recorder", "monitor", TRACKER)
#: the node processes that are managed (lifecycle) nodes: the launch configures and activates
#: them (the container brings its nodes up itself)
MANAGED: tuple[str, ...] = tuple(n for n, declared in NODE_PARAMETERS.items()
                                 if ManagedParameterValues in declared)
#: how long a managed node may take to serve its lifecycle services (its imports and the scene),
#: counted in the time the machine gave it (:meth:`Child.time_given_s`) [s]
LIFECYCLE_TIMEOUT_S = 60.0
#: how long one call of a managed node's ``get_state`` waits once the graph shows it [s]
PROBE_S = 1.0
#: how long a managed node may take to answer one transition (configure builds its estimator
#: or controller: well under a second here) [s]
TRANSITION_TIMEOUT_S = 20.0
#: the resolved scene the launch hands every node, beside the result file
RESOLVED_SCENE = "scene.resolved.yaml"
#: how a child asked to stop may end: cleanly, by the signal, or interrupted in its start-up
#: (:func:`stillframe.interrupts.exit_code`)
STOPPED_CODES = (0, -signal.SIGINT, -signal.SIGTERM, 128 + signal.SIGINT, 128 + signal.SIGTERM)
#: seconds a child gets to exit after SIGINT, then after SIGTERM, before SIGKILL
STOP_GRACE_S = 10.0
#: children that get longer to exit after SIGINT: the tracker finishes the windows due
STOP_GRACES_S: dict[str, float] = {TRACKER: TRACKER_STOP_S}
#: children that may also end so when asked to stop: the tracker, stopped again (SIGTERM after
#: its grace) with windows still due, writes each as given up (the launch warns) and exits so
STOP_CODES: dict[str, tuple[int, ...]] = {TRACKER: (*STOPPED_CODES, EXIT_GIVEN_UP)}
#: seconds of the machine's time (:meth:`Child.time_given_s`) a child that is still running
#: gets to log its ready line: a guard against a hung child, not a start-up time
READY_TIMEOUT_S = 120.0
#: the log line by which a helper child says it is ready (the nodes start after it)
READY_LINES: dict[str, str] = {"recorder": "Recording to", "monitor": "Monitor ready",
                               TRACKER: TRACKER_READY}
#: lines of a child's output kept to explain its death
TAIL_LINES = 15
#: how long the launch waits at the end of a run for its graph to name a writer a node reported
#: by GID only (across DDS vendors a node's name follows its writer by seconds) [s]
NAME_WAIT_S = 10.0
#: a writer GID as a node reports a writer its graph had not named (32 hex digits)
GID_TEXT = re.compile(r"\b[0-9a-f]{32}\b")
_PR_SET_PDEATHSIG = 1


class NodeDiedError(RuntimeError):
    """A child process ended before the run was over, or with a failure code."""

    def __init__(self, name: str, how: str, tail: Sequence[str], code: int | None = None
                 ) -> None:
        super().__init__(f"{name} died ({how})")
        self.name, self.how, self.tail, self.code = name, how, list(tail), code
        #: what the run still wrote (:meth:`Launcher.run` fills it in): ``"complete": false``
        self.partial: LaunchResult | None = None

    @classmethod
    def exited(cls, child: Child) -> NodeDiedError:
        code = child.proc.returncode
        how = (f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
               + (" before the end of the run" if code == 0 else ""))
        return cls(child.name, how, child.tail, code)

    def reported(self) -> StillframeError | None:
        """The error the node itself reported as it ended: its one ``error:`` line, of the
        kind its exit code says (:data:`stillframe.errors.BY_EXIT_CODE`); None when it ended
        otherwise (a signal, a crash)."""
        kind = BY_EXIT_CODE.get(self.code or 0)
        line = next((t for t in reversed(self.tail) if ": error: " in t), None)
        if kind is None or line is None:
            return None
        return kind(f"{self.name}: {line.split(': error: ', 1)[1]}")


def node_command(package: str, scene: Path, overrides: Sequence[str], mode: str, *,
                 params: dict[str, Any] | None = None, args: Sequence[str] = ()) -> list[str]:
    """``python -m PACKAGE ARGS --ros-args -p scene:=... -p overrides:=[...] -p mode:=...``
    (the package's ``__main__``: Ctrl-C answered from the process's first line,
    :func:`stillframe.interrupts.run_module`).

    Overrides go as a JSON list of strings (JSON is YAML, so rcl-style parsing keeps each
    ``key=value`` whole even when the value is itself a list); an empty list is left out
    because ROS parameters cannot be empty arrays."""
    argv = [sys.executable, "-m", package, *args, "--ros-args",
            "-p", f"scene:={scene}", "-p", f"mode:={mode}"]
    if overrides:
        argv += ["-p", f"overrides:={json.dumps(list(overrides))}"]
    for name, value in (params or {}).items():
        argv += ["-p", f"{name}:={json.dumps(value) if not isinstance(value, str) else value}"]
    return argv


#: a real-time run recorded above this rate gets :data:`RECORDED_RECORDER_ARGS` and ``dds``
#: where the user did not choose: a recorder beside a loop this fast costs it deadlines unless it
#: runs below the loop, and at the thesis's 32 Hz it costs nothing (docs/realtime.md,
#: "Recording beside a 1 kHz loop", has the measurements)
RECORDED_ABOVE_HZ = 200.0
#: the loop nodes' real-time practices in a real-time run unless ``--rt`` says otherwise, each
#: where the user may (:func:`stillframe.node_runtime.realtime.may`; docs/realtime.md)
REALTIME_PRACTICES = ",".join(DEFAULT_PRACTICES)


def recorded_default(specs: Sequence[str], *, record: bool, mode: str,
                     rate_hz: float) -> str | None:
    """The backend for the children the ``--backend`` values ``specs`` leave unset, when it is
    not the process's default: ``dds`` for a recorded real-time run above
    :data:`RECORDED_ABOVE_HZ` when neither ``STILLFRAME_RMW`` nor a ``--backend`` for every
    child chose one; None otherwise."""
    if (not fast_recorded(record=record, mode=mode, rate_hz=rate_hz)
            or any("=" not in spec for spec in specs)
            or environment.value(api.BACKEND_ENV) or api.backend_name() == "dds"):
        return None
    return "dds"


#: the recorder's priority arguments beside a recorded real-time run above
#: :data:`RECORDED_ABOVE_HZ` when ``--recorder-nice`` / ``--recorder-idle`` are not given: at
#: SCHED_IDLE it never takes a CPU from the loop's nodes (the loop paced by the clock leaves it
#: most of the machine: 8 – 17 us of CPU per message)
RECORDED_RECORDER_ARGS: tuple[str, ...] = ("--idle",)


def fast_recorded(*, record: bool, mode: str, rate_hz: float) -> bool:
    """Whether a run is a recorded real-time run above :data:`RECORDED_ABOVE_HZ`."""
    return record and mode == "realtime" and rate_hz > RECORDED_ABOVE_HZ


def practices_default(given: str | None, *, mode: str) -> str:
    """The loop nodes' practices: ``given`` (``--rt``) when the user gave it, else
    :data:`REALTIME_PRACTICES` in real time and none in lock-step (which keeps no deadline)."""
    if given is not None:
        return given
    return REALTIME_PRACTICES if mode == "realtime" else ""


def recorder_priority(given: Sequence[str] | None, *, mode: str, rate_hz: float) -> list[str]:
    """The recorder's ``stillframe record`` priority arguments: ``given`` when the user gave
    any, else :data:`RECORDED_RECORDER_ARGS` for a real-time run above
    :data:`RECORDED_ABOVE_HZ`, else none (``ros2 bag record``'s priority)."""
    if given is not None:
        return list(given)
    return list(RECORDED_RECORDER_ARGS) if fast_recorded(
        record=True, mode=mode, rate_hz=rate_hz) else []


def parse_backends(specs: Sequence[str], default: str | None = None) -> dict[str, str]:
    """The backend of every child from ``--backend`` values: ``BACKEND`` for all, then
    ``NAME=BACKEND`` for one (later values win); unset children use ``default``, else the
    process's default (``STILLFRAME_RMW``, else rclpy where importable). InputError names a bad
    value or a backend this machine lacks, before any process starts."""

    chosen = dict.fromkeys(BACKEND_TARGETS, default or api.backend_name())
    for spec in specs:
        name, _, backend = spec.rpartition("=")
        if name and name not in BACKEND_TARGETS:
            raise InputError(f"--backend {spec}: unknown node {name!r} "
                             f"(expected one of {', '.join(BACKEND_TARGETS)})")
        api.check_backend(backend, f"--backend {spec}")
        chosen.update({name: backend} if name else dict.fromkeys(BACKEND_TARGETS, backend))
    return chosen


def launch_discovery() -> str:
    """The discovery range of the launch, as the environment says (checked): ``SUBNET`` when
    ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is unset, as ``ros2 launch`` leaves it, so that a default
    Jazzy terminal on the same host (``ros2 topic list``) sees the run. The environment is not
    changed; the children inherit it as it is."""
    return discovery.discovery_range().value


def nodes_for(scene: Scene) -> list[str]:
    """The nodes a scene uses: sim_node always, the estimator and the controller unless the
    scene sets their type to ``none`` (an open-loop run such as a hammer test)."""
    used = {"sim_node": True, "estimator_node": scene.estimator.type != "none",
            "controller_node": scene.controller.type != "none"}
    return [name for name in NODES if used[name]]


def _prepare_child() -> None:
    """In the child before exec: SIGINT ignored until the child's own code installs its handler,
    and on Linux SIGTERM when the launcher dies (prctl). Python installs no KeyboardInterrupt
    handler for a SIGINT its parent ignored (the signal module's documentation), so a SIGINT
    forwarded while the child's interpreter is still starting (importing ``site``) cannot
    print a traceback from there; the node executables install theirs on their first line
    (:func:`stillframe.interrupts.run_module`), and :meth:`ProcessSet.stop` sends SIGTERM
    to a child that has none yet."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform == "linux":
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def catches_sigint(pid: int) -> bool:
    """Whether process ``pid`` has a handler of its own for SIGINT (``SigCgt`` in
    ``/proc/PID/status``); True where the kernel does not say."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return True
    caught = next((line.split()[1] for line in status.splitlines()
                   if line.startswith("SigCgt:")), None)
    return caught is None or bool(int(caught, 16) & (1 << (signal.SIGINT - 1)))


@dataclass
class Child:
    """One child process and the tail of its merged stdout/stderr."""

    name: str
    proc: subprocess.Popen
    tail: deque[str] = field(default_factory=lambda: deque(maxlen=TAIL_LINES))
    stop_requested: bool = False
    started_ns: int = field(default_factory=time.monotonic_ns)
    #: seconds it gets to exit after SIGINT
    grace_s: float = STOP_GRACE_S
    #: the exit codes of a clean stop once asked (:data:`STOP_CODES`)
    stopped_codes: tuple[int, ...] = STOPPED_CODES
    #: put back at the launcher's scheduling before it is asked to stop (a recorder that ran
    #: below the loop needs the CPU to close its bag on a busy machine)
    restore_on_stop: bool = False

    @property
    def pid(self) -> int:
        return self.proc.pid

    def exited(self) -> bool:
        """The child has ended (reaped: its exit code is known)."""
        return self.proc.poll() is not None

    def time_given_s(self) -> float:
        """Seconds since the start that the machine gave this child: the wall time less the
        time its main thread waited on a run queue (``/proc/PID/schedstat``). A timeout counted
        in it cannot be run out by a loaded machine that does not run the child (one fresh-clone
        run under load waited 60 s of wall time for a controller still importing), yet a child
        that sleeps or hangs uses it up as wall time. The wall time where the kernel keeps no
        schedstat."""
        return (time.monotonic_ns() - self.started_ns) * 1e-9 - self.waited_s()

    def waited_s(self) -> float:
        """Seconds its main thread has waited on a run queue (``/proc/PID/schedstat``); 0 where
        the kernel keeps no schedstat."""
        try:
            return int(Path(f"/proc/{self.pid}/schedstat").read_text().split()[1]) * 1e-9
        except (OSError, IndexError, ValueError):
            return 0.0


def run_ended(processes: ProcessSet, sim: Child, result_file: Path) -> bool:
    """Whether the run has ended: ``sim`` exited with 0 after writing ``result_file`` (it is
    then marked as asked to stop). Raises NodeDiedError for a child that exited otherwise. The
    failures are looked at first, the simulator's end second: a simulator that ends between the
    two looks is seen ended by the second, never as a child that died."""
    dead = processes.first_failure()
    if (dead is None or dead is sim) and sim.proc.poll() == 0 and result_file.exists():
        sim.stop_requested = True
        return True
    if dead is not None:
        raise NodeDiedError.exited(dead)
    return False


class ProcessSet:
    """Children started in order and stopped in reverse order; their output is prefixed with
    their name and handed to ``echo`` line by line (from reader threads)."""

    def __init__(self, echo: Callable[[str], None]) -> None:
        self.children: list[Child] = []
        self.echo = echo

    def start(self, name: str, argv: list[str], env_extra: dict[str, str] | None = None, *,
              grace_s: float = STOP_GRACE_S, restore_on_stop: bool = False,
              stopped_codes: tuple[int, ...] = STOPPED_CODES) -> Child:
        env = dict(os.environ, PYTHONUNBUFFERED="1", **(env_extra or {}))
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (env.get("PYTHONPATH", ""), str(REPO_ROOT)) if p)
        proc = subprocess.Popen(
            argv, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, errors="replace", process_group=0,
            preexec_fn=_prepare_child)
        child = Child(name, proc, grace_s=grace_s, restore_on_stop=restore_on_stop,
                      stopped_codes=stopped_codes)
        self.children.append(child)
        self.echo(f"started {name} (pid {proc.pid})")
        threading.Thread(target=self._pump, args=(child,), daemon=True).start()
        return child

    def _pump(self, child: Child) -> None:
        for line in child.proc.stdout:
            line = line.rstrip("\n")
            child.tail.append(line)
            self.echo(f"[{child.name}] {line}")

    def first_failure(self) -> Child | None:
        """The first child that exited although nobody asked it to, or with a failure code
        after being asked (a code other than 0 or death by the signal we sent)."""
        for child in self.children:
            code = child.proc.poll()
            if code is None:
                continue
            if not child.stop_requested or code not in child.stopped_codes:
                return child
        return None

    def stop(self, child: Child) -> None:
        """SIGINT (SIGTERM to a child still starting: one without a SIGINT handler yet,
        :func:`_prepare_child`), wait (the child's grace); SIGTERM, wait; SIGKILL. Always reaps
        the process."""
        child.stop_requested = True
        if child.restore_on_stop and not child.exited() and not restore_scheduling(child.pid):
            self.echo(f"{child.name} (pid {child.pid}) stays below the loop's priority while it "
                      "stops (raising it back needs CAP_SYS_NICE): on a busy machine it may not "
                      f"finish within {child.grace_s + 2 * STOP_GRACE_S:g} s")
        first = signal.SIGINT if catches_sigint(child.pid) else signal.SIGTERM
        for sig, grace in ((first, child.grace_s), (signal.SIGTERM, STOP_GRACE_S),
                           (signal.SIGKILL, STOP_GRACE_S)):
            if child.exited():
                break
            with contextlib.suppress(ProcessLookupError):
                child.proc.send_signal(sig)
            with contextlib.suppress(subprocess.TimeoutExpired):
                child.proc.wait(grace)
        child.proc.wait()

    def stop_all(self) -> None:
        """Stop every child still running, the last started first (the recorder, started
        first, closes its bag after the nodes are gone)."""
        for child in reversed(self.children):
            self.stop(child)

    def pids(self) -> list[int]:
        return [c.pid for c in self.children]


class StatusLine:
    """The live status line on a terminal (rewritten in place), or a plain line every
    ``every_s`` seconds otherwise; node output is printed above it."""

    def __init__(self, stream: Any = None, every_s: float = 5.0) -> None:
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty()
        self.every_s = every_s
        self.text = ""
        self._last: float | None = None     # when the last plain line was printed
        self._lock = threading.Lock()

    def width(self) -> int:
        """The terminal's width for the live line; plain lines are not cut."""
        return shutil.get_terminal_size((160, 24)).columns - 1 if self.live else 10_000

    def echo(self, line: str) -> None:
        with self._lock:
            self.stream.write(("\r\x1b[K" if self.live else "") + line + "\n")
            if self.live and self.text:
                self.stream.write(self.text)
            self.stream.flush()

    def update(self, text: str) -> None:
        with self._lock:
            self.text = text
            now = time.monotonic()
            if self.live:
                self.stream.write("\r\x1b[K" + text)
            elif self._last is None or now - self._last >= self.every_s:
                self.stream.write(text + "\n")
            else:
                return
            self._last = now
            self.stream.flush()

    def close(self) -> None:
        with self._lock:
            if self.live and self.text:
                self.stream.write("\r\x1b[K")
                self.stream.flush()
            self.text = ""


def status_text(statuses: dict[str, dict[str, str]], width: int = 160) -> str:
    """One line from the latest ``/diagnostics`` status of each node: ``name: k=v k=v | ...``
    (the name's last path component; the values of :data:`STATUS_KEYS` it has, all of them if
    none, as the node wrote them), cut to ``width``."""
    parts = []
    for name in sorted(statuses, key=_node_order):
        shown = {k: v for k, v in statuses[name].items() if k in STATUS_KEYS} or statuses[name]
        values = " ".join(f"{k}={v}" for k, v in shown.items())
        parts.append(f"{name.rsplit('/', 1)[-1].split(':')[-1].strip()}: {values}".strip())
    line = " | ".join(parts)
    return line if len(line) <= width else line[: width - 1] + "…"


def _node_order(name: str) -> tuple[int, str]:
    for i, node in enumerate(NODES):
        if node in name:
            return i, name
    return len(NODES), name


@dataclass
class LaunchResult:
    """What sim_node wrote at the end of the scene: its evaluation and the history file."""

    evaluation: dict[str, Any]
    result_file: Path
    history_file: Path
    diagnostics: dict[str, dict[str, str]] = field(default_factory=dict)
    #: the modal tracker's updates with ``track`` (:mod:`stillframe.app.tracking`)
    tracked_modes: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class LaunchOptions:
    """A launch: the scene, its overrides, the mode and where results go."""

    scene: Path
    overrides: list[str] = field(default_factory=list)
    #: the scene already loaded with its overrides and resolved (``model: auto`` chosen); None:
    #: the launcher does it, once, and hands the nodes the result (:data:`RESOLVED_SCENE`)
    resolved: Scene | None = None
    mode: str = "lockstep"
    result_file: Path = Path("result.json")
    record_dir: Path | None = None
    lockstep_timeout_s: float | None = None
    record_topics: list[str] = field(default_factory=list)
    #: the recorder's priority arguments (``stillframe record --nice N --idle``); None: the
    #: launch's default (:func:`recorder_priority`)
    recorder_args: list[str] | None = None
    backends: list[str] = field(default_factory=list)
    #: ``stillframe monitor`` arguments (ports) to run the monitor beside the nodes; None: none
    monitor_args: list[str] | None = None
    #: nodes in one process (``container_node``, intra-process handover): "" none, "pair"
    #: the estimator and the controller, "all" the simulator too
    compose: str = ""
    #: the loop nodes' real-time practices and CPUs (stillframe.node_runtime.realtime; "": none;
    #: None: the launch's default, :func:`practices_default`)
    rt: str | None = None
    rt_cpus: list[int] = field(default_factory=list)
    #: a command prefix per node that runs it on another host (``ip netns exec``,
    #: :mod:`stillframe.app.netns_lab`; the container on the estimator's); a node not named
    #: runs here
    hosts: dict[str, list[str]] = field(default_factory=dict)
    #: run the modal tracker beside the nodes (:mod:`stillframe.app.tracking`)
    track: bool = False
    #: where the loop nodes write their per-sample phase rings
    #: (:mod:`stillframe.node_runtime.phase_timing`); None: nowhere
    phase_log: Path | None = None
    #: False: the nodes time no phases (a twin run measuring the timing's own cost)
    phase_timing: bool = True

    @property
    def tracked_file(self) -> Path:
        return self.result_file.with_name("tracked_modes.jsonl")

    @property
    def adaptation_file(self) -> Path:
        """estimator_node's adaptation record (``adaptation.enabled``); its designs' model files
        go to ``designs/`` beside it."""
        return self.result_file.with_name("adaptation.json")


class Launcher:
    """Runs one :class:`LaunchOptions` to its end; ``node`` (a hidden DDS node on the same
    domain) may be given more subscriptions before :meth:`run` (the loop benchmark does)."""

    def __init__(self, options: LaunchOptions) -> None:

        if options.mode not in MODES:
            raise InputError(f"--mode {options.mode}: expected one of {', '.join(MODES)}")
        if options.record_dir is not None and options.record_dir.exists():
            raise InputError(f"--record {options.record_dir}: already exists")
        self.discovery = launch_discovery()
        self.options = options
        self.scene = options.resolved or resolve_model(
            load_scene(options.scene.resolve(), options.overrides))[0]
        # what a node would refuse, refused here, before any process starts
        check_loop(self.scene, mode=options.mode)
        if self.scene.adaptation.enabled and options.compose:
            raise InputError("--compose: with adaptation.enabled the estimator waits for the "
                             "controller to take each design, which one process cannot serve "
                             "while it waits; run without --compose")
        self.status = StatusLine()
        default = recorded_default(options.backends, record=options.record_dir is not None,
                                   mode=options.mode,
                                   rate_hz=self.scene.sensors.rate_hz)
        self.backends = parse_backends(options.backends, default)
        if default:
            self.status.echo(
                f"backend {default} for every child --backend does not name: a recorded "
                f"real-time loop at {self.scene.sensors.rate_hz:g} Hz misses far fewer deadlines "
                f"on {default} than on {api.backend_name()} (docs/realtime.md); "
                f"--backend {api.backend_name()} keeps {api.backend_name()}")
        rate_hz, record = self.scene.sensors.rate_hz, options.record_dir is not None
        self.recorder_args = recorder_priority(options.recorder_args, mode=options.mode,
                                               rate_hz=rate_hz)
        self.rt = practices_default(options.rt, mode=options.mode)
        if self.rt:
            self.status.echo(permissions_line(RealtimeOptions(
                parse_practices(self.rt), cpus=tuple(options.rt_cpus)))
                + ("; --rt none runs without them" if options.rt is None else ""))
        if record and options.recorder_args is None and self.recorder_args:
            self.status.echo(
                f"recorder run as `stillframe record {' '.join(self.recorder_args)}`: below "
                "the loop's nodes, it takes no CPU they want (docs/realtime.md); "
                "--recorder-nice 0 runs it as ros2 bag record does")
        self.processes = ProcessSet(self.status.echo)
        #: the run's token: every stamped sample of its nodes carries it, and they take no other
        self.token = new_run_token()
        self.node = api.create_node(running_graph.launcher_name(), argv=["stillframe"])
        self.created = time.monotonic()
        self.statuses: dict[str, dict[str, str]] = {}
        self.callers: dict[str, api.Node] = {}
        self.node.create_subscription("diagnostic_msgs/msg/DiagnosticArray", "/diagnostics",
                                      self._on_diagnostics, "default")

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            self.statuses[status.name] = {kv.key: kv.value for kv in status.values}

    def commands(self) -> list[tuple[str, list[str]]]:
        """(name, argv) of each child, in start order."""
        o = self.options
        sim_params: dict[str, Any] = {"result_file": str(o.result_file.resolve()),
                                      "command_writer": "controller_node"}
        if o.record_dir is not None:     # in real time too: the bag misses no first sample
            sim_params["await_recorder"] = [
                names.resolve_topic(t) for t in o.record_topics] or ["*"]
        if o.lockstep_timeout_s is not None:
            sim_params["lockstep_timeout_s"] = float(o.lockstep_timeout_s)
        # the nodes' last statuses reach this launch's report
        sim_params["await_status_reader"] = fqn("/", self.node.get_name())
        # the run's token, which only this launch's nodes know (docs/nodes.md, writer identity)
        shared: dict[str, Any] = {"run_token": self.token}
        scene = self.scene_file()
        children = []
        if o.record_dir is not None:
            children.append(("recorder", [sys.executable, "-m", "stillframe", "record", "-o",
                                          str(o.record_dir), "--use-sim-time",
                                          *self.recorder_args,
                                          *(o.record_topics or ["--all"])]))
        if o.monitor_args is not None:
            children.append(("monitor", [sys.executable, "-m", "stillframe", "monitor",
                                         "--dashboard", "--use-sim-time", "--scene", str(scene),
                                         *o.monitor_args]))
        if o.track:
            o.tracked_file.unlink(missing_ok=True)
            children.append((TRACKER, tracker_command(self.scene, o.tracked_file,
                                                      lockstep=o.mode != "realtime")))
        nodes = self.nodes()
        # the pair's container takes no real-time parameters (it composes two nodes' loops);
        # with the simulator in it, the simulator's practices are the process's
        rt = ({"rt": self.rt, **({"rt_cpus": o.rt_cpus} if o.rt_cpus else {})}
              if self.rt else {})
        sim = self.simulator()
        timing = {**({"phase_log": str(o.phase_log.resolve())} if o.phase_log else {}),
                  **({} if o.phase_timing else {"phase_timing": False})}
        adaptation = ({"adaptation_dir": str(o.adaptation_file.with_name("designs")),
                       "adaptation_record": str(o.adaptation_file)}
                      if self.scene.adaptation.enabled else {})
        children += [(name, [*o.hosts.get("estimator_node" if name == CONTAINER else name, []),
                             *node_command(name, scene, [], o.mode, params={
                                 **shared, **timing,
                                 **(rt if name in (sim, *LOOP) else {}),
                                 **(sim_params if name == sim else {}),
                                 **(adaptation if name == "estimator_node" else {}),
                                 **({"autostart": False} if name in MANAGED else {})},
                                 args=["all"] if name == sim == CONTAINER else [])])
                     for name in reversed(nodes)]
        return children

    def scene_file(self) -> Path:
        """Where the resolved scene goes: beside the result file."""
        return self.options.result_file.resolve().with_name(RESOLVED_SCENE)

    def write_scene(self) -> Path:
        """The resolved scene as YAML (:meth:`scene_file`), for every node to read (floats as
        ``repr`` writes them: the same numbers)."""
        path = self.scene_file()
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text(path, yaml.safe_dump(self.scene.to_dict(), sort_keys=False),
                   what="resolved scene")
        return path

    def nodes(self) -> list[str]:
        """The node processes of the scene, a container in place of those it composes."""
        o = self.options
        if o.compose not in COMPOSE:
            raise InputError(f"--compose {o.compose}: expected one of {', '.join(COMPOSE[1:])}")
        nodes = nodes_for(self.scene)
        if o.compose and {"estimator_node", "controller_node"} <= set(nodes):
            return [CONTAINER] if o.compose == "all" else ["sim_node", CONTAINER]
        return nodes

    def simulator(self) -> str:
        """The child that runs the simulator and writes the result."""
        return CONTAINER if self.options.compose == "all" and CONTAINER in self.nodes() \
            else "sim_node"

    def backend(self, child: str) -> str:
        """The middleware of a child (the container: the estimator's)."""
        return self.backends["estimator_node" if child == CONTAINER else child]

    def run(self) -> LaunchResult:
        """Start everything, wait for sim_node's result, stop the rest. Raises NodeDiedError,
        or KeyboardInterrupt after a clean stop when SIGINT/SIGTERM reached the launcher."""

        self.options.result_file.unlink(missing_ok=True)
        self.options.adaptation_file.unlink(missing_ok=True)
        try:
            running_graph.refuse_if_running(self.node, self.created, (*NODES, CONTAINER))
            self.write_scene()
            commands = self.commands()
            self.status.echo(f"discovery range {self.discovery}; backends " + ", ".join(
                f"{name} {self.backend(name)}" for name, _ in commands))
            mixed = len({self.backend(name) for name, _ in commands}) > 1
            for name, argv in commands:
                child = self.processes.start(name, argv, {"STILLFRAME_RMW": self.backend(name)},
                                             grace_s=STOP_GRACES_S.get(name, STOP_GRACE_S),
                                             restore_on_stop=name == "recorder",
                                             stopped_codes=STOP_CODES.get(name, STOPPED_CODES))
                if name in READY_LINES:
                    self._wait_for_line(child, READY_LINES[name])
                elif mixed:
                    self._wait_for_line(child, "middleware backend")
            managed = [name for name, _ in commands if name in MANAGED]
            simulator = self.simulator()
            sim = next(c for c in self.processes.children if c.name == simulator)
            watch = time.monotonic()
            while api.ok():
                self.node.spin_once(0.1)
                managed = [name for name in managed if not self.bring_up(name)]
                if time.monotonic() >= watch + running_graph.WATCH_S:
                    running_graph.check(self.node)
                    watch = time.monotonic()
                if self.statuses:
                    self.status.update(status_text(self.statuses, self.status.width()))
                if run_ended(self.processes, sim, self.options.result_file):
                    break
            else:
                raise KeyboardInterrupt
            for child in reversed(self.processes.children):
                self.processes.stop(child)
            self.node.spin_once(0.0)    # the nodes' last statuses, written as they stopped
            if (dead := self.processes.first_failure()) is not None:
                raise NodeDiedError.exited(dead)
            self._name_writers()
        except NodeDiedError as exc:
            exc.partial = self._partial(exc)
            raise
        finally:
            self.processes.stop_all()
            self.status.close()
            for caller in self.callers.values():
                caller.destroy_node()
            self.node.destroy_node()
        return self._result()

    def bring_up(self, name: str) -> bool:
        """``configure``, then ``activate`` the managed node ``name`` through its
        ``change_state`` service once its ``get_state`` answers, as a lifecycle-aware ``ros2
        launch`` emits the transitions; False while it does not answer yet (the launch goes on
        meanwhile), NodeDiedError when it refuses, or answers nothing within
        :data:`LIFECYCLE_TIMEOUT_S` of the time the machine gave it. The calls go through a
        node of the target's backend (services do not cross DDS vendors)."""
        child = next(c for c in self.processes.children if c.name == name)
        caller = self._caller(self.backend(name))
        prefix = f"{DEFAULT_NAMESPACE}/{name}"
        # the graph first (no wait): a node that serves no lifecycle services yet must not hold
        # the launcher's loop, which watches the children and takes the statuses meanwhile
        served = {service for service, _ in caller.get_service_names_and_types_by_node(
            name, DEFAULT_NAMESPACE)}
        if f"{prefix}/get_state" not in served or caller.call_service(
                "lifecycle_msgs/srv/GetState", f"{prefix}/get_state",
                messages.new("lifecycle_msgs/srv/GetState_Request"), PROBE_S) is None:
            if child.time_given_s() > LIFECYCLE_TIMEOUT_S:
                raise NodeDiedError(name, f"no lifecycle services after "
                                          f"{LIFECYCLE_TIMEOUT_S:g} s", child.tail)
            return False
        for transition, goal in (("configure", "inactive"), ("activate", "active")):
            request = messages.new("lifecycle_msgs/srv/ChangeState_Request",
                                   transition=messages.new("lifecycle_msgs/msg/Transition",
                                                           label=transition))
            # a node killed mid-transition ends the wait at once, not after the timeout
            response = caller.call_service("lifecycle_msgs/srv/ChangeState",
                                           f"{prefix}/change_state", request,
                                           TRANSITION_TIMEOUT_S, give_up=child.exited)
            if response is None and not child.exited() and self._state(caller, prefix) == goal:
                continue    # done, but its reply was lost (a lossy network drops replies too)
            if response is None or not response.success:
                if child.exited():   # died meanwhile: say how
                    raise NodeDiedError.exited(child)
                raise NodeDiedError(name, f"{transition} " + (
                    "failed" if response else "not answered"), child.tail)
        self.status.echo(f"{name}: configured and active")
        return True

    @staticmethod
    def _state(caller: api.Node, prefix: str) -> str | None:
        """The managed node's state label from its ``get_state`` (a path already seen to
        answer), or None when it does not answer."""
        response = caller.call_service("lifecycle_msgs/srv/GetState", f"{prefix}/get_state",
                                       messages.new("lifecycle_msgs/srv/GetState_Request"),
                                       TRANSITION_TIMEOUT_S)
        return None if response is None else str(response.current_state.label)

    def _caller(self, backend: str) -> api.Node:
        """The launcher's node on ``backend`` (made on first use)."""
        if self.node.backend == backend:
            return self.node
        if backend not in self.callers:
            self.callers[backend] = api.create_node(
                f"_stillframe_lifecycle_{backend}_{os.getpid()}", argv=["stillframe"],
                backend=backend)
        return self.callers[backend]

    def _wait_for_line(self, child: Child, text: str, timeout_s: float = READY_TIMEOUT_S) -> None:
        """Wait for ``child`` to log ``text`` before starting the next: nodes start once the
        recorder is recording and the monitor serving (:data:`READY_LINES`); with mixed vendors,
        a node starts once the previous one has its participant ('middleware backend'), because
        a Cyclone and a Fast DDS participant created in the same instant can take the same
        participant index and then never discover each other. The limit counts the time the
        machine gave the child (:meth:`Child.time_given_s`): a recorder below the loop on a busy
        machine may wait long for its first CPU, a hung one runs the limit out."""
        while not any(text in line for line in child.tail):
            if child.exited():
                raise NodeDiedError.exited(child)
            if not api.ok():
                raise KeyboardInterrupt
            if child.time_given_s() > timeout_s:
                raise NodeDiedError(child.name, f"no {text!r} after {timeout_s:g} s of the "
                                    "machine's time", child.tail)
            time.sleep(0.05)

    def _partial(self, died: NodeDiedError) -> LaunchResult:
        """After a node died: stop the others (SIGINT first: the simulator writes the samples
        it ran, the recorder closes its bag), then write what there is to the result file,
        marked ``"complete": false``, with the dead node, how each other child stopped, the
        nodes' last statuses and the bag."""
        self.processes.stop_all()
        self.node.spin_once(0.0)     # the statuses the nodes wrote as they stopped
        path = self.options.result_file
        try:
            written = json.loads(path.read_text())
        except (OSError, ValueError):
            written = {}        # the simulator died, or stopped before its first sample
        stopped = {c.name: _how_stopped(c.proc.returncode) for c in self.processes.children
                   if c.name != died.name}
        evaluation = {**written, "complete": False, "died": {"node": died.name, "how": died.how},
                      "stopped": stopped, "diagnostics": dict(self.statuses)}
        if self.options.record_dir is not None:
            evaluation["bag"] = _bag_state(self.options.record_dir, written.get("steps"))
        with contextlib.suppress(OSError, InputError):
            write_text(path, json.dumps(evaluation, indent=2) + "\n", what="result file")
        history = path.with_suffix(".npz")
        return LaunchResult(evaluation, path, history, dict(self.statuses))

    def _name_writers(self) -> None:
        """Name, in the nodes' reports, the writers a node could give by GID only (its graph had
        not named them yet: across DDS vendors a node's name comes seconds after its writer,
        longer than a short run), from the launch's own graph, waiting for it at most
        :data:`NAME_WAIT_S`: the result file and the statuses then name every writer."""
        path = self.options.result_file
        text = path.read_text() if path.is_file() else ""
        gids = set(GID_TEXT.findall(text + json.dumps(self.statuses)))
        names: dict[str, str] = {}
        deadline = time.monotonic() + NAME_WAIT_S
        while gids - names.keys() and time.monotonic() < deadline and api.ok():
            self.node.spin_once(0.1)
            for topic, _ in self.node.get_topic_names_and_types():
                names.update({ep.endpoint_gid.hex(): fqn(ep.node_namespace, ep.node_name)
                              for ep in self.node.get_publishers_info_by_topic(topic)
                              if ep.endpoint_gid.hex() in gids
                              and ep.node_name not in UNNAMED_NODES})
        for gid, name in names.items():
            text = text.replace(gid, name)
            self.statuses = json.loads(json.dumps(self.statuses).replace(gid, name))
        if names:
            path.write_text(text)

    def _result(self) -> LaunchResult:
        path = self.options.result_file
        try:
            evaluation = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"sim_node's result file {path}: cannot read it ({exc})") from None
        if self.options.record_dir is not None:
            evaluation["bag"] = _bag_state(self.options.record_dir, evaluation.get("steps"))
        if self.scene.adaptation.enabled:
            try:
                evaluation["adaptation"] = json.loads(self.options.adaptation_file.read_text())
            except (OSError, ValueError) as exc:
                evaluation["adaptation"] = {"error": f"no adaptation record ({exc})"}
        return LaunchResult(evaluation, path, path.with_suffix(".npz"), dict(self.statuses),
                            read_tracked(self.options.tracked_file) if self.options.track else [])


def _how_stopped(code: int | None) -> str:
    if code is None:
        return "still running"
    return f"ended by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"


def _bag_state(bag: Path, steps: int | None) -> dict[str, Any]:
    """Whether the recorder closed its bag (metadata written), how many messages it holds,
    what the recorder found missing (samples per topic, its stalls; its ``custom_data``) and,
    when the simulator ran ``steps`` samples, how many of each of its per-sample topics the bag
    does not hold (``not_recorded``: the samples it sent, less the bag's messages of the topic;
    this also counts what a stamp grid cannot show, the samples after the last one the bag holds
    or before its first)."""
    try:
        meta = load_metadata(bag)
    except BagError:
        return {"path": str(bag), "closed": False,
                "note": f"not closed: recover it with stillframe bag reindex {bag}"}
    state: dict[str, Any] = {"path": str(bag), "closed": True, "messages": meta.message_count}
    for name, key in (("missing_samples", MISSING_KEY), ("recorder_stalls", STALLS_KEY)):
        with contextlib.suppress(KeyError, ValueError):
            state[name] = json.loads(meta.custom_data[key])
    if isinstance(steps, int):
        held = {t.name: t.message_count for t in meta.topics}
        state["not_recorded"] = {topic: max(steps - held[topic], 0)
                                 for topic in PER_SAMPLE if topic in held}
    return state


def run_scene(scene: Path, overrides: Sequence[str] = (), *, out: Path,
              prepare: Callable[[Any], None] | None = None, **options: Any) -> LaunchResult:
    """Launch ``scene`` with ``overrides`` through the three nodes to its end; sim_node's
    results go to ``out`` (``result.json``, ``result.npz``, beside the resolved scene the nodes
    read). ``options`` are the other fields of :class:`LaunchOptions` (the mode, the recorder,
    the backends, …), checked there. ``prepare(node)`` may subscribe the launcher's hidden node
    to more topics before the children start."""
    out.mkdir(parents=True, exist_ok=True)
    launcher = Launcher(LaunchOptions(scene, list(overrides), result_file=out / "result.json",
                                      **options))
    if prepare is not None:
        prepare(launcher.node)
    return launcher.run()
