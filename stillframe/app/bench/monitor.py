"""``stillframe bench monitor``: the loop's ``bench loop`` figures with and without a monitor.

The LQG scene through the three nodes, without and with ``stillframe monitor --dashboard`` beside
them, watched from a process of their own: the dashboard's data polled twice a second (what an
open browser tab does) and, unless ``--watch dashboard``, a Foxglove client subscribed to every
topic (counting the messages: a viewer decodes in its own process).
Two figures of ``bench loop``: the full scene in lock-step (steps per second of sim_node's loop,
without process start-up), and real time at ``--rate`` (samples answered within the period and
the command latency p99, seen by an observer in this process). Each repeat runs both kinds in
both orders (without first, then with first, alternately) so that drift of the machine's load
cancels; the figures are the medians over the repeats, and the monitor's cost is the ratio
of the medians, against a bound of 10 %.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import multiprocessing
import socket
import sys
import tempfile
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.arguments import add_json_argument, emit_json, seconds
from stillframe.app.bench.loop import SCENE, observer_backend, realtime
from stillframe.errors import InputError
from stillframe.middleware import api
from stillframe.monitor.foxglove_client import Capture, capture
from stillframe.text_table import format_table

POLL_PERIOD_S = 0.5


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench monitor``, its arguments and :func:`run` as its action to
    ``benches``."""
    parser = benches.add_parser("monitor",
                                help="the loop's figures with and without a monitor attached",
                                description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--repeats", type=int, default=3, metavar="N",
                        help="runs of each kind, in alternating order (default 3)")
    parser.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                        help="sample rate of the real-time runs (default 1000)")
    parser.add_argument("--duration", type=seconds, default=10.0, metavar="S",
                        help="seconds of each real-time run (default 10)")
    parser.add_argument("--watch", choices=WATCH, default="every-topic",
                        help="what watches the monitor besides the dashboard page: a Foxglove "
                             "client on every topic (default), or nothing else ('dashboard')")
    parser.add_argument("--idle", action=argparse.BooleanOptionalAction, default=True,
                        help="run the monitor at SCHED_IDLE, as launch --monitor does (default; "
                             "--no-idle: at nice 10, launch --no-monitor-idle)")
    parser.add_argument("--backend", default="dds", choices=api.BACKENDS,
                        help="middleware of the nodes, the monitor and the observer (default dds, "
                             "the backend bench loop's goals are measured on)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


#: what watches the monitor: --watch value -> Foxglove client's topics (None: every topic)
WATCH: dict[str, list[str] | None] = {"dashboard": [], "every-topic": None}


class Watchers:
    """A Foxglove client of ``topics`` (None: every topic) and a dashboard poller, in a process
    of their own (as a viewer is: it must not take the observer's interpreter), until stopped."""

    def __init__(self, ws_port: int, http_port: int, topics: list[str] | None) -> None:
        spawn = multiprocessing.get_context("spawn")
        self._stop = spawn.Event()
        self._results: multiprocessing.Queue = spawn.Queue()
        self._process = spawn.Process(target=watch, daemon=True, args=(
            ws_port, http_port, topics, self._stop, self._results))
        self._process.start()

    def stop(self) -> dict[str, int]:
        """Stop watching: the client's messages and topics and the dashboard's polls."""
        self._stop.set()
        figures = self._results.get(timeout=60)
        self._process.join(30)
        return figures


def watch(ws_port: int, http_port: int, topics: list[str] | None, stop: Any,
          results: multiprocessing.Queue) -> None:
    """The watchers' process (:class:`Watchers`)."""
    seen, polls = Capture(), 0

    async def client(until: asyncio.Event) -> None:
        while not until.is_set():
            try:
                await capture(f"ws://127.0.0.1:{ws_port}", topics, until, seen, decode=False)
            except OSError:
                await asyncio.sleep(0.1)  # the monitor is not up yet

    def poll() -> None:
        nonlocal polls
        with urllib.request.urlopen(f"http://127.0.0.1:{http_port}/data", timeout=5) as answer:
            answer.read()
        polls += 1

    async def main() -> None:
        until = asyncio.Event()
        task = asyncio.create_task(client(until))
        while not stop.is_set():
            with contextlib.suppress(OSError):  # the monitor is not up yet
                await asyncio.to_thread(poll)
            await asyncio.sleep(POLL_PERIOD_S)
        until.set()
        await task

    asyncio.run(main())
    results.put({"client_messages": sum(len(m) for m in seen.messages.values()),
                 "client_topics": len(seen.messages), "dashboard_polls": polls})


#: the monitor may cost the loop at most this fraction of a figure
BOUND = 0.10


def one_run(out: Path, mode: str, watched: str | None, rate_hz: float, duration: float,
            backend: str, idle: bool = False) -> dict[str, Any]:
    """One launch of the LQG scene on ``backend``: lock-step (the full scene) or real time at
    ``rate_hz`` for ``duration`` s (``bench loop``'s real-time run); with ``watched`` (a
    :data:`WATCH` key), a monitor and its watchers beside the nodes."""
    from stillframe.app.launcher import run_scene

    watchers, monitor_args = None, None
    if watched is not None:
        ws_port, http_port = free_port(), free_port()
        watchers = Watchers(ws_port, http_port, WATCH[watched])
        monitor_args = ["--port", str(ws_port), "--dashboard-port", str(http_port),
                        *(["--idle"] if idle else [])]
    try:
        if mode == "realtime":
            figures = realtime(rate_hz, duration, out, backend, monitor_args=monitor_args)
        else:
            with observer_backend(backend):
                evaluation = run_scene(SCENE, out=out, mode=mode, backends=[backend],
                                       monitor_args=monitor_args).evaluation
            figures = {"steps": evaluation["steps"],
                       "steps_per_s": evaluation["steps"] / evaluation["wall_s"]}
    finally:
        if watchers is not None:
            figures_of_watchers = watchers.stop()
    if watchers is not None:
        figures.update(figures_of_watchers)
    return figures


#: (mode, figure, label, True if larger is better)
FIGURES: tuple[tuple[str, str, str, bool], ...] = (
    ("lockstep", "steps_per_s", "lock-step steps/s", True),
    ("realtime", "within_period_pct", "real time: answered within the period [%]", True),
    ("realtime", "p99_us", "real time: latency p99 [us]", False),
)


def compare(runs: dict[str, dict[str, list[dict[str, Any]]]]) -> list[dict[str, Any]]:
    """Per figure: the medians without and with the monitor, their ratio, and whether the
    monitor costs at most :data:`BOUND` of it."""
    rows = []
    for mode, key, label, larger_is_better in FIGURES:
        without = float(np.median([r[key] for r in runs[mode]["without"]]))
        with_ = float(np.median([r[key] for r in runs[mode]["with"]]))
        ratio = with_ / without
        cost = 1.0 - ratio if larger_is_better else ratio - 1.0
        rows.append({"figure": label, "mode": mode, "key": key, "without": without,
                     "with": with_, "with_over_without": ratio, "monitor_cost": cost,
                     "within_bound": bool(cost <= BOUND)})
    return rows


def delivered(runs: list[dict[str, Any]], duration: float) -> dict[str, float]:
    """What the watchers got in the real-time runs with a monitor (medians): a monitor that
    costs the loop nothing because it sends nothing would show here."""
    return {"client_messages_per_s": float(np.median([r["client_messages"] for r in runs]))
            / duration,
            "client_topics": float(np.median([r["client_topics"] for r in runs])),
            "dashboard_polls_per_s": float(np.median([r["dashboard_polls"] for r in runs]))
            / duration}


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    if args.repeats < 1:
        raise InputError(f"bench monitor: --repeats must be >= 1, got {args.repeats}")
    if not args.rate > 0:
        raise InputError(f"bench monitor: --rate must be > 0 Hz, got {args.rate:g}")
    if not args.duration >= 1.0:
        raise InputError(f"bench monitor: --duration must be >= 1 s, got {args.duration:g}")
    api.check_backend(args.backend, f"bench monitor --backend {args.backend}")
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {
        mode: {"without": [], "with": []} for mode in ("lockstep", "realtime")}
    total = 4 * args.repeats
    with tempfile.TemporaryDirectory(prefix="stillframe-bench-monitor-") as tmp:
        for i in range(args.repeats):
            order = ("without", "with") if i % 2 == 0 else ("with", "without")
            for mode in runs:
                for kind in order:
                    done = sum(len(r) for m in runs.values() for r in m.values())
                    print(f"[{done + 1}/{total}] {mode} {kind} a monitor", file=sys.stderr)
                    runs[mode][kind].append(one_run(
                        Path(tmp) / f"{mode}-{kind}{i}", mode,
                        args.watch if kind == "with" else None, args.rate, args.duration,
                        args.backend, args.idle))
    rows = compare(runs)
    got = delivered(runs["realtime"]["with"], args.duration)
    if args.json:
        emit_json({"backend": args.backend, "watch": args.watch, "idle": args.idle,
                   "rate_hz": args.rate, "duration_s": args.duration, "repeats": args.repeats,
                   "bound": BOUND, "runs": runs, "figures": rows, "delivered": got})
        return 0
    print(format_table(
        ["figure", "without", "with", "with / without", "monitor's cost", "goal"],
        [[r["figure"], f"{r['without']:.1f}", f"{r['with']:.1f}",
          f"{r['with_over_without']:.3f}", f"{100 * r['monitor_cost']:+.1f} %",
          f"<= {100 * BOUND:.0f} %: {'met' if r['within_bound'] else 'NOT met'}"]
         for r in rows]))
    print(f"medians of {args.repeats} runs each on {args.backend}, watched by: {args.watch}; "
          f"real time at {args.rate:g} Hz for {args.duration:g} s; the monitor "
          f"{'at SCHED_IDLE' if args.idle else 'at nice 10'}")
    print(f"delivered in real time: {got['client_messages_per_s']:.0f} messages/s on "
          f"{got['client_topics']:.0f} topics to the Foxglove client, "
          f"{got['dashboard_polls_per_s']:.1f} dashboard polls/s")
    return 0
