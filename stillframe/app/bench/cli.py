"""``stillframe bench cli``: ``stillframe topic list`` with and without the graph daemon.

A peer process publishes a few topics on this ``ROS_DOMAIN_ID``; then ``--calls`` runs of
``stillframe topic list --no-daemon`` (a node of its own, waiting until discovery settles) and
``--calls`` warm runs of ``stillframe topic list`` (answered by the daemon) take turns, so that a
busy machine slows both alike. It prints the median and the slowest of each, their ratio, the
first (cold) call that started the daemon, and whether every answer listed the peer's topics.
A daemon running before is stopped first and the one started here is stopped at the end.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

from stillframe.app.arguments import add_json_argument, emit_json
from stillframe.errors import InputError
from stillframe.text_table import format_table

PEER_TOPICS = ("/bench_cli/a", "/bench_cli/b", "/bench_cli/c")
PEER = f"""
from stillframe.middleware.api import create_node, spin
node = create_node("bench_cli_peer", argv=["peer", "--ros-args", "--log-level", "warn"])
pubs = [node.create_publisher("std_msgs/msg/Float64", t, 10) for t in {PEER_TOPICS!r}]
print("ready", flush=True)
spin(node)
node.destroy_node()
"""


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench cli``, its arguments and :func:`run` as its action to ``benches``."""
    parser = benches.add_parser("cli", help="topic list with and without the graph daemon",
                                description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--calls", type=int, default=10, metavar="N",
                        help="calls of each kind, taking turns (default 10)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def timed(*args: str) -> tuple[float, list[str]]:
    """Wall seconds of one ``stillframe`` call and its output lines."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "stillframe", *args], capture_output=True,
                          text=True, timeout=120)
    took = time.perf_counter() - start
    if done.returncode != 0:
        raise InputError(f"bench cli: stillframe {' '.join(args)} failed: "
                         f"{done.stderr.strip().splitlines()[-1:]}")
    return took, done.stdout.splitlines()


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    if args.calls < 1:
        raise InputError(f"bench cli: --calls must be >= 1, got {args.calls}")
    from stillframe.app import graph_daemon

    graph_daemon.stop()
    peer = subprocess.Popen([sys.executable, "-c", PEER], stdout=subprocess.PIPE, text=True)
    try:
        if peer.stdout.readline().strip() != "ready":
            raise InputError("bench cli: the peer process did not start")
        cold, listed = timed("topic", "list")
        complete = [set(PEER_TOPICS) <= set(listed)]
        direct, warm = [], []
        for i in range(args.calls):
            print(f"[{i + 1}/{args.calls}] topic list without and with the daemon",
                  file=sys.stderr, flush=True)
            for runs, extra in ((direct, ["--no-daemon"]), (warm, [])):
                took, listed = timed("topic", "list", *extra)
                runs.append(took)
                complete.append(set(PEER_TOPICS) <= set(listed))
    finally:
        graph_daemon.stop()
        peer.terminate()
        peer.wait(timeout=30)
    result = {
        "calls": args.calls, "cold_s": cold,
        "direct_median_s": statistics.median(direct), "direct_max_s": max(direct),
        "daemon_median_s": statistics.median(warm), "daemon_max_s": max(warm),
        "ratio": statistics.median(direct) / statistics.median(warm),
        "complete": all(complete), "direct_s": direct, "daemon_s": warm,
    }
    if args.json:
        emit_json(result)
        return 0
    print(format_table(
        ["topic list", "median [s]", "max [s]"],
        [["without the daemon (--no-daemon)", f"{result['direct_median_s']:.3f}",
          f"{result['direct_max_s']:.3f}"],
         ["with the daemon (warm)", f"{result['daemon_median_s']:.3f}",
          f"{result['daemon_max_s']:.3f}"]]))
    print(f"ratio without / with the daemon: {result['ratio']:.1f}; first call (starts the "
          f"daemon) {cold:.3f} s; every answer complete: {'yes' if result['complete'] else 'NO'}")
    return 0
