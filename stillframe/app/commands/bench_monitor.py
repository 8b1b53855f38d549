"""``stillframe bench monitor``: the lock-step loop with and without a monitor attached.

The full LQG scene through the three nodes, alternately without and with ``stillframe monitor
--dashboard`` beside them, a Foxglove client subscribed to every topic and the dashboard's data
polled twice a second (what an open browser tab does); the client counts the messages without
decoding them (a viewer's decoding happens in its own process). Figures: sim_node's loop wall time
(without process start-up), steps per second, and the ratio with / without, best of
``--repeats`` runs each.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import socket
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

from stillframe.app.commands.bench_loop import SCENE
from stillframe.app.commands.common import add_json_argument, emit_json
from stillframe.errors import InputError
from stillframe.monitor.foxglove_client import Capture, capture
from stillframe.text_table import format_table

POLL_PERIOD_S = 0.5


def register(benches: argparse._SubParsersAction) -> None:
    parser = benches.add_parser("monitor", help="lock-step loop speed with and without a monitor",
                                description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--repeats", type=int, default=2, metavar="N",
                        help="runs of each kind, alternating (default 2)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class Watchers:
    """A Foxglove client of every topic and a dashboard poller, in a thread, until stopped."""

    def __init__(self, ws_port: int, http_port: int) -> None:
        self.seen = Capture()
        self.polls = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=asyncio.run, args=(self._main(ws_port, http_port),),
                                        daemon=True)
        self._thread.start()

    async def _main(self, ws_port: int, http_port: int) -> None:
        until = asyncio.Event()
        client = asyncio.create_task(self._client(f"ws://127.0.0.1:{ws_port}", until))
        while not self._stop.is_set():
            with contextlib.suppress(OSError):  # the monitor is not up yet
                await asyncio.to_thread(self._poll, f"http://127.0.0.1:{http_port}/data")
            await asyncio.sleep(POLL_PERIOD_S)
        until.set()
        await client

    async def _client(self, url: str, until: asyncio.Event) -> None:
        while not until.is_set():
            try:
                await capture(url, None, until, self.seen, decode=False)
            except OSError:
                await asyncio.sleep(0.1)  # the monitor is not up yet

    def _poll(self, url: str) -> None:
        with urllib.request.urlopen(url, timeout=5) as response:
            response.read()
        self.polls += 1

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(30)


def one_run(out: Path, monitored: bool) -> dict[str, Any]:
    from stillframe.app.launcher import run_scene

    if not monitored:
        evaluation = run_scene(SCENE, [], out, "lockstep").evaluation
        return {"wall_s": evaluation["wall_s"], "steps": evaluation["steps"]}
    ws_port, http_port = free_port(), free_port()
    watchers = Watchers(ws_port, http_port)
    try:
        evaluation = run_scene(SCENE, [], out, "lockstep", monitor_args=[
            "--port", str(ws_port), "--dashboard-port", str(http_port)]).evaluation
    finally:
        watchers.stop()
    return {"wall_s": evaluation["wall_s"], "steps": evaluation["steps"],
            "client_messages": sum(len(m) for m in watchers.seen.messages.values()),
            "client_topics": len(watchers.seen.messages), "dashboard_polls": watchers.polls}


def run(args: argparse.Namespace) -> int:
    if args.repeats < 1:
        raise InputError(f"bench monitor: --repeats must be >= 1, got {args.repeats}")
    runs: dict[str, list[dict[str, Any]]] = {"without": [], "with": []}
    with tempfile.TemporaryDirectory(prefix="stillframe-bench-monitor-") as tmp:
        for i in range(args.repeats):
            for kind in runs:
                print(f"run {i + 1}/{args.repeats}: lock-step LQG {kind} a monitor",
                      file=sys.stderr)
                started = time.perf_counter()
                runs[kind].append(one_run(Path(tmp) / f"{kind}{i}", kind == "with"))
                print(f"  {runs[kind][-1]['wall_s']:.2f} s loop, "
                      f"{time.perf_counter() - started:.1f} s in all", file=sys.stderr)
    best = {kind: min(rs, key=lambda r: r["wall_s"]) for kind, rs in runs.items()}
    ratio = best["without"]["wall_s"] / best["with"]["wall_s"]
    if args.json:
        emit_json({"runs": runs, "best": best, "speed_with_over_without": ratio})
        return 0
    print(format_table(
        ["", "loop wall [s]", "steps", "steps/s", "client msgs", "topics", "dashboard polls"],
        [[kind, f"{b['wall_s']:.2f}", b["steps"], f"{b['steps'] / b['wall_s']:.0f}",
          b.get("client_messages", "-"), b.get("client_topics", "-"),
          b.get("dashboard_polls", "-")] for kind, b in best.items()]))
    print(f"speed with a monitor / without: {ratio:.3f} (best of {args.repeats} each)")
    return 0
