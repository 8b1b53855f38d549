"""``stillframe bench faults``: the loop across three hosts under loss, delay and reordering.

Each loop node in its own network namespace on one bridge (``launch --netns``); per fault on
every host's incoming link (loss 1/5/10/30 %, delay 5 ± 2 ms, reordering): lock-step wall time
and whether the result is bit-identical to the one-process loop, and at 100 Hz in real time
sim_node's deadline misses, the estimate's RMS error against the truth and the displacement
reductions (:mod:`stillframe.app.bench.fault_runs`). Needs root, iproute2 and iptables.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

from stillframe.app.arguments import add_json_argument, emit_json, seconds
from stillframe.app.launch_cli import add_netns_arguments
from stillframe.app.net_faults import FAULTS, check_tools, fault_named
from stillframe.errors import InputError
from stillframe.text_table import format_table

MODES = ("lockstep", "realtime")


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench faults``, its arguments and :func:`run` as its action to
    ``benches``."""
    parser = benches.add_parser("faults", help="the loop on three hosts (network namespaces) "
                                               "under network faults",
                                description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--duration", type=seconds, default=10.0, metavar="S",
                        help="simulated seconds of each run, control from half-time "
                             "(default 10)")
    parser.add_argument("--fault", dest="faults", action="append", default=[], metavar="NAME",
                        help="run only this fault (repeatable): "
                             + ", ".join(f"'{f.name}'" for f in FAULTS).replace("%", "%%"))
    parser.add_argument("--only", choices=MODES, default=None,
                        help="run only the lock-step or only the real-time runs")
    parser.add_argument("--backend", dest="backends", action="append", default=[],
                        metavar="[NODE=]BACKEND", help="as for launch (default dds)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="scene override for every run, as for launch "
                        "(e.g. actuators.delay_periods=3: a playout delay the LQG predicts over)")
    add_netns_arguments(parser, switch=False)
    add_json_argument(parser)
    parser.set_defaults(func=run)


def _pct(values: list[float]) -> str:
    return " ".join(f"{v:.1f}" for v in values)


def table(rows: list[dict[str, Any]]) -> str:
    """The text table of the fault ``rows``: lock-step wall time and bit-identity, real-time steps,
    misses, estimate RMS errors [mm, mrad] and reductions per fault."""
    lines = []
    for r in rows:
        ls, rt = r.get("lockstep", {}), r.get("realtime", {})
        est = rt.get("estimate", {})
        lines.append([
            r["fault"],
            f"{ls['wall_s']:.2f}" if ls else "-",
            ("yes" if ls["bit_identical"] else "NO") if ls else "-",
            ls.get("complete", "-"),
            rt.get("steps", "-"), rt.get("deadline_misses", "-"), rt.get("overruns", "-"),
            f"{est['rms_floors_m'] * 1e3:.3f}" if est else "-",
            f"{est['rms_phi_rad'] * 1e3:.2f}" if est else "-",
            _pct(rt["reduction_pct"]) if rt else "-"])
    return format_table(
        ["fault", "lock-step wall [s]", "bit-identical", "complete", "RT steps",
         "deadline misses", "overruns", "est. RMS x [mm]", "est. RMS φ [mrad]",
         "RT x red. % (1 2 3)"], lines)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    from stillframe.app.bench.fault_runs import SCENE, run_bench
    from stillframe.app.netns_lab import joined, lab
    from stillframe.config.scene import load_scene

    if not args.duration >= 2.0:
        raise InputError("bench faults: --duration must be >= 2 s")
    load_scene(SCENE, args.overrides)       # a bad --set is one line before the lab is built
    faults = [fault_named(name) for name in args.faults] or list(FAULTS)
    check_tools()
    modes = [args.only] if args.only else list(MODES)
    with tempfile.TemporaryDirectory(prefix="stillframe-bench-faults-") as tmp, \
            lab(args.netns_prefix) as made, joined(made):
        rows = run_bench(made, faults, args.duration, Path(tmp), modes=modes,
                         backends=args.backends, overrides=args.overrides)
    if args.json:
        emit_json({"duration_s": args.duration, "overrides": args.overrides, "rows": rows})
    else:
        print(table(rows))
    return 0
