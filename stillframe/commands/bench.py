"""``stillframe bench NAME``: benchmarks that print figures as ratios against a baseline.

Each module in :data:`BENCHES` exposes ``register(subparsers)`` like a top-level command.
"""

from __future__ import annotations

import argparse
import importlib

BENCHES: tuple[str, ...] = (
    "stillframe.commands.bench_transport",
    "stillframe.commands.bench_identify",
    "stillframe.commands.bench_identify_hammer",
    "stillframe.commands.bench_loop",
    "stillframe.commands.bench_monitor",
    "stillframe.commands.bench_fidelity",
    "stillframe.commands.bench_speed",
    "stillframe.commands.bench_montecarlo",
)


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("bench", help="benchmarks (ratios against a baseline in the same run)")
    benches = parser.add_subparsers(dest="bench", metavar="NAME")
    benches.required = True
    for name in BENCHES:
        importlib.import_module(name).register(benches)
