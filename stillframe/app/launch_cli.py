"""What the commands that launch the loop through its nodes share (``launch``, ``demo``,
``reproduce``, ``experiment``, ``adapt`` and the benchmarks that launch): their arguments, the
evaluation table, and the one line a node's death or a partial result gives."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from stillframe.app.arguments import (
    NICE_RANGE,
    emit_json,
    seconds,
    whole,
)
from stillframe.app.launcher import MODES, REALTIME_PRACTICES, RECORDED_ABOVE_HZ
from stillframe.app.net_faults import FAULTS
from stillframe.config.scene import Scene
from stillframe.errors import BagError, InputError
from stillframe.text_table import format_table


def add_launch_arguments(parser: argparse.ArgumentParser) -> None:
    """``--mode`` and ``--lockstep-timeout`` (shared with ``reproduce`` and ``demo``)."""
    parser.add_argument("--mode", choices=MODES, default="lockstep",
                        help="lockstep: deterministic, as fast as the nodes go (default); "
                             "realtime: paced by the wall clock")
    parser.add_argument("--lockstep-timeout", type=seconds, default=None, metavar="S",
                        help="lock-step: the longest sim_node waits for one sample's command "
                             "while its peers are on the graph; past it the run ends, "
                             "incomplete, exit code 7 (default: 60 s)")
    parser.add_argument("--backend", dest="backends", action="append", default=[],
                        metavar="[NODE=]BACKEND",
                        help="middleware of every node (dds or rclpy; default: STILLFRAME_RMW, "
                             "else rclpy where installed, but dds for a --record'ed real-time "
                             f"run above {RECORDED_ABOVE_HZ:g} Hz), or of one node: "
                             "sim_node=dds "
                             "(repeatable; also estimator_node, controller_node, recorder)")


def add_netns_arguments(parser: argparse.ArgumentParser, switch: bool = True) -> None:
    """``--netns`` (with ``switch``) and ``--netns-prefix`` (shared with ``bench faults``)."""
    if switch:
        parser.add_argument("--netns", action="store_true",
                            help="run each node in its own network namespace, joined by a "
                                 "bridge (three hosts on one; needs root; docs/reliability.md)")
    parser.add_argument("--netns-prefix", default=None, metavar="P",
                        help="name prefix of the network namespaces (default sf<pid>)")


def add_fault_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--fault NAME`` to ``parser``: one of the network faults of
    :data:`~stillframe.app.net_faults.FAULTS` on every host's incoming link (with ``--netns``)."""
    parser.add_argument("--fault", default=None, metavar="NAME",
                        help="with --netns: a network fault on every host's incoming link: "
                             + ", ".join(f"'{f.name}'" for f in FAULTS).replace("%", "%%"))


def evaluation_table(evaluation: dict[str, Any], scene: Scene) -> str:
    """Floors as rows: peaks without and with control, the reductions, the scene's reference."""
    ev = scene.evaluation
    red = evaluation["reduction_pct"]
    before = evaluation.get("peak_uncontrolled", {})
    after = evaluation.get("peak_controlled", {})

    def ref(values: Sequence[float], i: int) -> str:
        return f"{values[i]:.2f}" if len(values) == 3 else "-"

    def peak(table: dict[str, list[float]], key: str, i: int) -> str:
        return f"{table[key][i]:.4g}" if key in table else "-"

    rows = [[f"floor {i + 1}",
             peak(before, "displacement", i), peak(after, "displacement", i),
             f"{red['displacement'][i]:.2f}", ref(ev.reference_displacement_pct, i),
             peak(before, "velocity", i), peak(after, "velocity", i),
             f"{red['velocity'][i]:.2f}", ref(ev.reference_velocity_pct, i)]
            for i in range(3)]
    return format_table(["", "x off [m]", "x on [m]", "x red. %", "thesis %",
                         "v off [m/s]", "v on [m/s]", "v red. %", "thesis %"], rows)


def print_evaluation(evaluation: dict[str, Any], scene: Scene) -> None:
    """Print the evaluation a launch returned: the steady-state peaks and reductions per floor
    against the scene's baseline, the peak command, the steps and the wall time (and in real time
    the deadline misses and overruns)."""
    ev = scene.evaluation
    baseline = (f"the {ev.window:g} s before control starts" if ev.baseline == "before_start"
                else f"the last {ev.window:g} s of a run without control")
    print(f"scene {scene.name}: steady-state peaks, last {ev.window:g} s with control against "
          f"{baseline}:")
    print(evaluation_table(evaluation, scene))
    counters = ("deadline_misses", "overruns") if evaluation.get("mode") == "realtime" else ()
    extras = [f"{key} {evaluation[key]}" for key in counters if key in evaluation]
    print(f"peak command {evaluation['peak_command']:.4g}; {evaluation['steps']} steps in "
          f"{evaluation['wall_s']:.2f} s wall" + (f"; {', '.join(extras)}" if extras else ""))


def add_compose_arguments(parser: argparse.ArgumentParser) -> None:
    """``--compose`` and ``--compose-all`` (shared with ``bench loop``)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--compose", dest="compose", action="store_const", const="pair",
                       default="", help="estimator and controller in one process "
                       "(container_node): samples handed over in-process, still published")
    group.add_argument("--compose-all", dest="compose", action="store_const", const="all",
                       help="simulator, estimator and controller in one process: one sample is "
                            "one chain of calls, still published on every topic")


def add_realtime_arguments(parser: argparse.ArgumentParser, *, launch: bool = True) -> None:
    """``--rt [PRACTICES]`` and ``--rt-cpus`` (shared with ``bench loop``, which has no default
    practices: ``launch`` False)."""
    from stillframe.node_runtime.realtime import PRACTICES

    practice = REALTIME_PRACTICES
    default = (f"{practice} in --mode realtime, each where you may (one line says which), "
               "none in lock-step" if launch else "none")
    parser.add_argument("--rt", nargs="?", const=practice, default=None, metavar="PRACTICES",
                        help=f"real-time mode for the loop nodes: '--rt' alone is {practice}; "
                             "'all', 'none', or a comma list of "
                             f"{', '.join(PRACTICES)} (docs/realtime.md; default {default})")
    parser.add_argument("--rt-cpus", default="", metavar="CPUS",
                        help="with --rt affinity: pin the loop nodes to these CPUs (e.g. 1)")


def add_recorder_arguments(parser: argparse.ArgumentParser) -> None:
    """``--recorder-nice N`` and ``--recorder-idle`` (shared with ``bench loop``)."""
    parser.add_argument("--recorder-nice", type=whole(*NICE_RANGE), default=None, metavar="N",
                        help="with --record: the recorder's CPU priority lowered by N, 0..19 "
                             "(`stillframe record --nice`; default 0, or what docs/realtime.md "
                             f"gives a real-time run above {RECORDED_ABOVE_HZ:g} Hz)")
    parser.add_argument("--recorder-idle", action="store_true",
                        help="with --record: the recorder at SCHED_IDLE (`stillframe record "
                             "--idle`); either option replaces the default")


def realtime_arguments(args: argparse.Namespace) -> tuple[str | None, list[int]]:
    """The checked ``--rt`` practices (None: not given, the launch's default) and ``--rt-cpus``
    CPUs."""
    from stillframe.node_runtime.realtime import parse_cpus, parse_practices

    practices = None if args.rt is None else parse_practices(args.rt)
    try:
        cpus = [int(c) for c in args.rt_cpus.split(",") if c.strip()]
    except ValueError:
        raise InputError(f"--rt-cpus {args.rt_cpus!r}: expected CPU numbers, e.g. 1 or 0,1") \
            from None
    if cpus and not practices:
        raise InputError("--rt-cpus needs --rt")
    return (None if practices is None else ",".join(sorted(practices)),
            list(parse_cpus(cpus)) if cpus else [])


#: how ``stillframe record`` states a bag failure (a full disk), which ``launch`` passes on
RECORDER_ERROR = "stillframe record: error: "


def report_death(command: str, exc: Exception) -> int:
    """One line naming the dead node, then the last lines it printed; a node that ended on an
    error of its own (a lock-step peer gone, a plant that diverged, a scene it refused) gives
    that line and its exit code; a recorder that ended on a bag failure (a full disk: the bag
    closed with what fit) gives its own line and exit 3."""
    if (reported := getattr(exc, "reported", lambda: None)()) is not None:
        print(f"stillframe {command}: error: {reported}", file=sys.stderr)
        return reported.exit_code
    if getattr(exc, "name", "") == "recorder" and (line := next(
            (t for t in getattr(exc, "tail", []) if t.startswith(RECORDER_ERROR)), None)):
        print(f"stillframe {command}: error: recorder: {line.removeprefix(RECORDER_ERROR)}",
              file=sys.stderr)
        return BagError.exit_code
    print(f"stillframe {command}: error: {exc}", file=sys.stderr)
    for line in getattr(exc, "tail", []):
        print(f"  {line}", file=sys.stderr)
    return 1


def print_partial(evaluation: dict[str, Any], scene: Scene, args: argparse.Namespace) -> None:
    """What a run whose node died still has (``"complete": false``): the JSON document with
    ``--json``, else one line on what was kept; the file under ``--out`` in both cases."""
    if args.json:
        emit_json({"scene": scene.name, **evaluation})
        return
    steps = evaluation.get("steps")
    planned = evaluation.get("steps_planned")
    kept = [f"{steps} of {planned} steps" if steps is not None else "no samples"]
    if (bag := evaluation.get("bag")) is not None:
        kept.append(f"bag {bag['path']} ({bag['messages']} messages)" if bag["closed"]
                    else bag["note"])
    if args.out is not None:
        kept.append(f"written to {args.out / 'result.json'}")
    print(f"scene {scene.name}: partial result (complete: false): {'; '.join(kept)}")


def bag_incomplete(bag: dict[str, Any] | None) -> str:
    """One line on what the launch's bag lacks (the recorder's counts, and the simulator's
    samples the bag does not hold beyond those, as
    :func:`stillframe.recording.recorder.completeness` says it), "" when nothing."""
    from stillframe.recording.recorder import completeness

    if not bag or not bag.get("closed"):
        return ""
    stalls = bag.get("recorder_stalls", {})
    missing = bag.get("missing_samples", {})
    lacks = {t: max(n - missing.get(t, 0), 0) for t, n in bag.get("not_recorded", {}).items()}
    line = completeness(missing, stalls.get("count", 0), stalls.get("longest_s", 0.0),
                        lacks=lacks)
    return f"the bag {bag['path']} {line}" if line else ""


def recorder_args(args: argparse.Namespace) -> list[str] | None:
    """The recorder's priority arguments from ``--recorder-nice`` and ``--recorder-idle``; None
    when neither was given (the launch's default)."""
    if args.recorder_nice is None and not args.recorder_idle:
        return None
    return ["--nice", str(args.recorder_nice or 0)] + (["--idle"] if args.recorder_idle else [])


def monitor_args(args: argparse.Namespace) -> list[str]:
    """``stillframe monitor``'s arguments from launch's ``--monitor-*`` options."""
    rate = [] if args.monitor_max_rate is None else ["--max-rate", f"{args.monitor_max_rate:g}"]
    idle = ["--idle"] if args.monitor_idle else []
    return ["--port", str(args.monitor_port), "--dashboard-port", str(args.dashboard_port), *rate,
            *idle]
