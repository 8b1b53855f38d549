"""``stillframe identify-daisy``: OKID + ERA, OKID + ERA/DC and OKID + ERA refined as an
output-error model beside N4SID on real measured data (the DaISy steel subframe), validated on a
held-out half. See :mod:`stillframe.identification.daisy`."""

from __future__ import annotations

import argparse
import sys

from stillframe.app.arguments import add_json_argument, emit_json
from stillframe.files import check_output
from stillframe.text_table import format_table


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe identify-daisy``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser(
        "identify-daisy", help="identification report on the DaISy steel-subframe record",
        description="Identify the DaISy 96-013 steel subframe on the first half of the record "
                    "with OKID + ERA, OKID + ERA/DC and N4SID (nfoursid); validate on the second "
                    "half.")
    parser.add_argument("--data", metavar="FILE", default=None,
                        help="flexible_structure_dat.mat (default: daisy/ in $STILLFRAME_DATASETS, "
                             "else the copy shipped in datasets/)")
    add_json_argument(parser)
    parser.add_argument("--plots", metavar="DIR", default=None, help="write PNG figures here")
    parser.add_argument("--progress", action="store_true",
                        help="show progress on stderr (default: when stderr is a terminal)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Identify the DaISy subframe with each method, validate on the held-out half and print the
    fits; exit code 0."""
    import numpy as np

    from stillframe.app.arguments import Progress
    from stillframe.identification import daisy

    check_output("--plots", args.plots, folder=True)

    progress = Progress(args.progress or sys.stderr.isatty())
    result = daisy.report(args.data, progress)
    methods = result["methods"]
    agreement = {m: daisy.match_dominant(methods["n4sid"]["modes"], methods[m]["modes"], 3)
                 for m in daisy.OKID_METHODS}
    if args.plots:
        from pathlib import Path

        from stillframe.identification import plots

        out = Path(args.plots)
        n = result["samples"]["validation"]
        simulated = {k: v["simulated"] for k, v in methods.items() if v["simulated"] is not None}
        plots.validation(np.arange(n) * result["dt"], result["measured"], simulated,
                         [f"y{i}" for i in result["outputs"]], out / "daisy_validation.png",
                         span=0.1)
        plots.mode_comparison({k: v["modes"] for k, v in methods.items()},
                              out / "daisy_modes.png")
        progress(f"plots written to {out}")
    for name, entry in methods.items():
        del entry["simulated"]
        for warning in entry["warnings"]:
            print(f"stillframe identify-daisy: warning: {name}: {warning}", file=sys.stderr)
    del result["measured"]
    result["dominant_mode_agreement"] = agreement
    if args.json:
        emit_json(result)
        return 0
    print(f"{result['dataset']}: identified on samples 1..{result['samples']['identification']}"
          f", validated on the remaining {result['samples']['validation']}; order "
          f"{result['order']}; outputs {result['outputs']} of 28; dt = 1/1024 s")
    rows = [[name, entry["observer_order"] or "-", f"{entry['seconds']:.2f}",
             *(f"{f:.1f}" for f in entry["fit_percent"] or []),
             f"{entry['mean_fit_percent']:.1f}" if entry["fit_percent"] else "unstable"]
            for name, entry in methods.items()]
    print("\nvalidation fit [%] (simulation from the measured input, held-out half)")
    print(format_table(["method", "p", "time [s]", *(f"y{i}" for i in result["outputs"]),
                        "mean"], rows))
    print("\ndominant modes (frequency [Hz] / damping ratio, by resonance peak)")
    count = max(len(e["modes"]) for e in methods.values())
    mode_rows = [[k + 1, *(f"{e['modes'][k]['frequency_hz']:.2f} / "
                           f"{e['modes'][k]['damping_ratio']:.4f}"
                           if k < len(e["modes"]) else "" for e in methods.values())]
                 for k in range(min(count, 8))]
    print(format_table(["rank", *methods], mode_rows))
    print("\nN4SID's three most dominant modes, nearest OKID mode (relative difference)")
    for method, rows in agreement.items():
        print(f"  {method}: " + ", ".join(
            f"{r['reference_hz']:.2f} -> {r['other_hz']:.2f} Hz "
            f"({100 * r['relative_difference']:.2f} %)" for r in rows))
    return 0
