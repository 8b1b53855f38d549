"""``stillframe launch SCENE``: the three nodes as separate processes over DDS, to the end.

Prints the live status from ``/diagnostics`` on stderr and, at the end of the scene, the
evaluation sim_node wrote: steady-state peaks per floor with and without control and the
reductions (thesis eq. 5.233, 5.287); ``--json`` prints it as one document ``{"reduction_pct":
{"displacement": [...], "velocity": [...]}, "peak_command": ..., "complete": true, "steps": ...,
"wall_s": ..., "degraded": false, "degraded_reasons": [], "foreign_writers": [], ...}``. A degraded
run (:mod:`stillframe.app.run_verdict`) ends with a warning line giving the reasons, and with
``--strict`` with exit code 6; so does a run whose nodes refused the samples of writers not of the
run (``foreign_writers``: each node, topic, the writers fully qualified and how many samples were
refused), in either mode: exit 0 with the warning (the figures are the loop's own nodes'), 6 with
``--strict``. With ``--record`` the document's ``bag`` says what the recorder found missing
(``missing_samples`` per topic, ``recorder_stalls``), and a bag that misses samples ends the run
with a warning line. A node that ended on an error of its own passes on its line and exit code (7: a
lock-step run whose peer left the graph or stopped answering; 4: a plant that diverged). Exit code 1
names a node that died otherwise (how: its exit code or signal) after the others were stopped
cleanly; what the run still has (the samples the simulator ran, the statuses, the closed bag) is
printed and written under ``--out`` as a partial result marked ``"complete": false``. 130 follows
Ctrl-C (every child stopped and reaped).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from stillframe import interrupts
from stillframe.app.arguments import (
    add_scene_arguments,
    emit_json,
    scene_from_args,
    whole,
)
from stillframe.app.launch_cli import (
    add_compose_arguments,
    add_fault_argument,
    add_launch_arguments,
    add_netns_arguments,
    add_realtime_arguments,
    add_recorder_arguments,
    bag_incomplete,
    monitor_args,
    print_evaluation,
    print_partial,
    realtime_arguments,
    recorder_args,
    report_death,
)
from stillframe.app.run_verdict import foreign_warning, foreign_writers, verdict
from stillframe.app.tracking import given_up
from stillframe.errors import DegradedRunError, InputError
from stillframe.files import check_output


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe launch``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser(
        "launch", help="run a scene through sim_node, estimator_node and controller_node over DDS",
        description="Start the three nodes as separate processes on the current ROS_DOMAIN_ID, "
                    "show their status, stop cleanly on Ctrl-C, print the evaluation.")
    add_scene_arguments(parser)
    add_launch_arguments(parser)
    parser.add_argument("--track", action="store_true",
                        help="run the modal tracker beside the nodes (identification's "
                        "modal_tracker); --json then has tracked_modes")
    parser.add_argument("--record", type=Path, default=None, metavar="DIR",
                        help="also record every topic into this rosbag2 directory (MCAP)")
    parser.add_argument("--record-topic", dest="record_topics", action="append", default=[],
                        metavar="TOPIC", help="with --record: record only this topic "
                                              "(repeatable)")
    add_recorder_arguments(parser)
    parser.add_argument("--monitor", action="store_true",
                        help="also run `stillframe monitor --dashboard` (Foxglove bridge and "
                             "live dashboard on 127.0.0.1)")
    parser.add_argument("--monitor-port", type=whole(0, 65535), default=8765, metavar="P",
                        help="with --monitor: Foxglove WebSocket port (default 8765; 0: any)")
    parser.add_argument("--dashboard-port", type=whole(0, 65535), default=8080, metavar="P",
                        help="with --monitor: dashboard port (default 8080; 0: any)")
    parser.add_argument("--monitor-max-rate", type=float, default=None, metavar="HZ",
                        help="with --monitor: samples forwarded per second and topic at most "
                             "(stillframe monitor --max-rate; 0: every sample)")
    parser.add_argument("--monitor-idle", action=argparse.BooleanOptionalAction, default=True,
                        help="with --monitor: run it at SCHED_IDLE, on CPU time the nodes leave "
                             "unused (stillframe monitor --idle; default on: a viewer beside the "
                             "loop gives up samples, never loop time)")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="keep sim_node's result.json and result.npz (histories) here")
    parser.add_argument("--strict", action="store_true",
                        help="a degraded real-time run (deadline misses, watchdog zeros, refused "
                             "commands, no command in time, mostly zero actuation) or a run "
                             "beside a foreign writer (its samples refused) exits with code 6 "
                             "instead of only warning")
    add_compose_arguments(parser)
    add_realtime_arguments(parser)
    add_netns_arguments(parser)
    add_fault_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Launch the scene's nodes as processes, print the live status and the evaluation; exit code 0,
    a dead node's code (:func:`report_death`), 130/143 when interrupted, or a
    :class:`~stillframe.errors.DegradedRunError` with ``--strict`` and warnings."""
    from stillframe.app.launcher import NodeDiedError, run_scene
    from stillframe.app.net_faults import hosts_if

    check_output("--out", args.out, folder=True)
    check_output("--record", args.record, folder=True)

    scene = scene_from_args(args)
    rt, rt_cpus = realtime_arguments(args)
    if args.record_topics and args.record is None:
        raise InputError("--record-topic needs --record DIR")
    if recorder_args(args) is not None and args.record is None:
        raise InputError("--recorder-nice and --recorder-idle need --record DIR")
    with tempfile.TemporaryDirectory(prefix="stillframe-launch-") as tmp:
        try:
            with hosts_if(args.netns, args.netns_prefix, args.fault) as hosts:
                result = run_scene(Path(args.scene), args.overrides, out=args.out or Path(tmp),
                                   mode=args.mode, record_dir=args.record,
                                   lockstep_timeout_s=args.lockstep_timeout, resolved=scene,
                                   record_topics=args.record_topics, backends=args.backends,
                                   monitor_args=monitor_args(args) if args.monitor else None,
                                   compose=args.compose, rt=rt, rt_cpus=rt_cpus, hosts=hosts,
                                   track=args.track, recorder_args=recorder_args(args))
        except NodeDiedError as exc:
            code = report_death("launch", exc)
            if exc.partial is not None:
                print_partial(exc.partial.evaluation, scene, args)
            return code
        except KeyboardInterrupt as exc:
            print("stillframe launch: interrupted; every node stopped", file=sys.stderr)
            return interrupts.exit_code(exc)
    reasons = verdict(result.evaluation, result.diagnostics)
    if incomplete := bag_incomplete(result.evaluation.get("bag")):
        print(f"stillframe launch: warning: {incomplete}", file=sys.stderr)
    if lost := given_up(result.tracked_modes):
        print(f"stillframe launch: warning: {lost}", file=sys.stderr)
    foreign = foreign_writers(result.evaluation, result.diagnostics)
    if args.json:
        emit_json({"scene": scene.name, **result.evaluation, "degraded": bool(reasons),
                   "degraded_reasons": reasons, "foreign_writers": foreign,
                   "diagnostics": result.diagnostics,
                   **({"tracked_modes": result.tracked_modes} if args.track else {})})
    elif "reduction_pct" in result.evaluation:
        print_evaluation(result.evaluation, scene)
    else:
        print(f"scene {scene.name}: {result.evaluation.get('steps')} steps, no controller")
    warnings = ([f"degraded {args.mode} run, its figures are not the controller's: "
                 f"{'; '.join(reasons)}"] if reasons else []) + (
        [foreign_warning(foreign)] if foreign else [])
    if warnings and args.strict:
        raise DegradedRunError(" | ".join(warnings))
    for warning in warnings:
        print(f"stillframe launch: warning: {warning}", file=sys.stderr)
    return 0
