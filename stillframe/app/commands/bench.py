"""``stillframe bench NAME``: benchmarks that print figures as ratios against a baseline.

Each module in :data:`BENCHES` exposes ``register(subparsers)`` like a top-level command.
"""

from __future__ import annotations

import argparse
import importlib

BENCHES: tuple[str, ...] = (
    "stillframe.app.commands.bench_transport",
    "stillframe.app.commands.bench_identify",
    "stillframe.app.commands.bench_identify_hammer",
    "stillframe.app.commands.bench_loop",
    "stillframe.app.commands.bench_scaling",
    "stillframe.app.commands.bench_hops",
    "stillframe.app.commands.bench_monitor",
    "stillframe.app.commands.bench_fidelity",
    "stillframe.app.commands.bench_speed",
    "stillframe.app.commands.bench_montecarlo",
    "stillframe.app.commands.bench_faults",
    "stillframe.app.commands.bench_soak",
    "stillframe.app.commands.bench_cli",
    "stillframe.app.commands.bench_controllers",
    "stillframe.app.commands.bench_writers",
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench`` to ``sub`` and, below it, each benchmark of :data:`BENCHES` by its
    own ``register``."""
    parser = sub.add_parser("bench", help="benchmarks (ratios against a baseline in the same run)")
    benches = parser.add_subparsers(dest="bench", metavar="NAME")
    benches.required = True
    for name in BENCHES:
        importlib.import_module(name).register(benches)
