"""``stillframe bench NAME``: benchmarks that print figures as ratios against a baseline.

Each module of :data:`stillframe.app.bench.BENCHES` exposes ``register(subparsers)`` like a
top-level command.
"""

from __future__ import annotations

import argparse
import importlib

from stillframe.app.bench import BENCHES


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench`` to ``sub`` and, below it, each benchmark of :data:`BENCHES` by its
    own ``register``."""
    parser = sub.add_parser("bench", help="benchmarks (ratios against a baseline in the same run)")
    benches = parser.add_subparsers(dest="bench", metavar="NAME")
    benches.required = True
    for name in BENCHES:
        importlib.import_module(name).register(benches)
