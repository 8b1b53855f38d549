"""``stillframe bench identify``: the identification sweep (:mod:`stillframe.identification.sweep`).

The cases and their scoring are in :mod:`stillframe.identification.sweep`.

Random shear buildings (2–5 modes, some closely spaced), SNR × record length cells, several seeds
per cell; stillframe's default path (what ``stillframe identify`` does without options: OKID +
ERA/DC, order auto, prediction-error refinement), its ``--fast`` path without the refinement,
N4SID (``nfoursid``) and python-control (``markov`` + ``era``) on the same records. Per cell and
method: median and 90th-percentile worst-mode frequency and damping errors, wrong, warned and
silently wrong runs, runs silently worse than N4SID by more than 1.5×, and stillframe's 95 %
interval coverage. Terminal table, ``--json``, heat maps with ``--plots DIR``; ``--quick`` runs a
small subset, ``--snr`` and ``--samples`` pick cells. The sweep's modules (python-control, nfoursid,
matplotlib) are imported in ``run``: every CLI command registers this module at start-up.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stillframe.app.arguments import add_executor_arguments, add_json_argument, emit_json
from stillframe.errors import InputError
from stillframe.files import check_output, save_figure
from stillframe.text_table import format_table

FIGURES: tuple[tuple[str, str, float], ...] = (
    ("frequency_error_median", "median worst-mode frequency error [%]", 100.0),
    ("frequency_error_p90", "90th-percentile worst-mode frequency error [%]", 100.0),
    ("damping_error_median", "median worst-mode damping error [%]", 100.0),
    ("damping_error_p90", "90th-percentile worst-mode damping error [%]", 100.0),
    ("silently_wrong", "silently wrong runs [-]", 1.0),
)
LABELS = {"stillframe": "stillframe (default)", "stillframe_okid": "stillframe --fast",
          "n4sid": "N4SID", "python_control": "python-control",
          "ssi_cov": "stillframe ssi-cov (output-only)",
          "pyoma2_ssi_cov": "pyOMA2 SSIcov (output-only)"}


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench identify``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("identify", help="identification sweep: stillframe vs N4SID vs "
                                             "python-control on random shear buildings")
    parser.add_argument("--quick", action="store_true",
                        help="SNR 40, 15 dB x lengths 1024, 256 x 3 seeds")
    parser.add_argument("--seeds", type=int, default=None,
                        help="seeds per cell (default 10, --quick 3)")
    parser.add_argument("--snr", type=float, nargs="+", default=None, metavar="DB",
                        help="only these SNR cells (dB, from 40 30 20 15 10)")
    parser.add_argument("--samples", type=int, nargs="+", default=None, metavar="N",
                        help="only these record-length cells (from 4096 1024 512 256)")
    parser.add_argument("--plots", type=Path, default=None, metavar="DIR",
                        help="write one heat-map PNG per method and figure")
    add_json_argument(parser)
    add_executor_arguments(parser)
    parser.set_defaults(func=run)


def _percent(value: float) -> str:
    return "inf" if not np.isfinite(value) else f"{100 * value:.3g}"


def _coverage(cell: dict) -> str:
    if "ci_coverage_frequency" not in cell:
        return "-"
    return f"{100 * cell['ci_coverage_frequency']:.0f}/{100 * cell['ci_coverage_damping']:.0f}"


def heat_maps(table: list[dict], directory: Path) -> list[Path]:
    """One PNG per method and figure: SNR down, record length across."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from stillframe.identification.sweep import METHODS
    snrs = sorted({row["snr_db"] for row in table}, reverse=True)
    lengths = sorted({row["samples"] for row in table}, reverse=True)
    index = {(row["snr_db"], row["samples"]): row for row in table}
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for method in METHODS:
        for key, title, scale in FIGURES:
            grid = np.array([[index[(s, n)][method][key] * scale for n in lengths]
                             for s in snrs], dtype=float)
            shown = np.where(np.isfinite(grid), grid, np.nan)
            fig, ax = plt.subplots(figsize=(5.5, 4))
            image = ax.imshow(np.log10(np.maximum(shown, 1e-3)) if scale != 1.0 else shown,
                              cmap="viridis", aspect="auto")
            for i in range(len(snrs)):
                for j in range(len(lengths)):
                    value = grid[i, j]
                    text = "inf" if not np.isfinite(value) else f"{value:.3g}"
                    ax.text(j, i, text, ha="center", va="center", color="w", fontsize=8)
            ax.set_xticks(range(len(lengths)), [str(n) for n in lengths])
            ax.set_yticks(range(len(snrs)), [f"{s:g}" for s in snrs])
            ax.set_xlabel("record length [samples]")
            ax.set_ylabel("SNR [dB]")
            ax.set_title(f"{LABELS[method]}: {title}", fontsize=9)
            fig.colorbar(image, ax=ax, label="error [log10 %]" if scale != 1.0 else "runs [-]")
            fig.tight_layout()
            path = directory / f"identify_sweep_{method}_{key}.png"
            save_figure(fig, path, dpi=100)
            plt.close(fig)
            paths.append(path)
    return paths


def _subset(flag: str, chosen: list | None, cells: tuple) -> tuple:
    """The cells asked for with ``flag`` (all when not given); refuses values not in the sweep."""
    if chosen is None:
        return cells
    unknown = [c for c in chosen if c not in cells]
    if unknown:
        raise InputError(f"{flag} {unknown[0]:g}: not a cell of the sweep "
                         f"({', '.join(f'{c:g}' for c in cells)})")
    return tuple(c for c in cells if c in chosen)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    check_output("--plots", args.plots, folder=True)
    from stillframe.identification.sweep import (
        LENGTHS,
        METHODS,
        QUICK_LENGTHS,
        QUICK_SEEDS,
        QUICK_SNR_DB,
        SEEDS,
        SNR_DB,
        cases,
        run_case,
        run_cases,
        summarize,
    )

    if args.quick:
        snrs, lengths, seeds = QUICK_SNR_DB, QUICK_LENGTHS, QUICK_SEEDS
    else:
        snrs, lengths, seeds = SNR_DB, LENGTHS, SEEDS
    if args.seeds is not None and args.seeds < 1:
        raise InputError(f"--seeds {args.seeds}: must be a positive integer")
    seeds = args.seeds or seeds
    from stillframe.studies.executor import mapper

    snrs = _subset("--snr", args.snr, snrs)
    lengths = _subset("--samples", args.samples, lengths)
    spread = mapper(args.workers, args.scheduler, "bench identify")
    items = cases(snrs, lengths, seeds)
    start = time.perf_counter()
    results = spread(run_case, items) if spread else run_cases(run_case, items)
    elapsed = time.perf_counter() - start
    table = summarize(results)
    paths = heat_maps(table, args.plots) if args.plots else []
    if args.json:
        emit_json({"cells": table, "runs": results, "elapsed_s": elapsed,
                   "plots": [str(p) for p in paths]})
        return 0
    rows = []
    for row in table:
        for method in METHODS:
            cell = row[method]
            rows.append([f"{row['snr_db']:g}", row["samples"], LABELS[method],
                         _percent(cell["frequency_error_median"]),
                         _percent(cell["frequency_error_p90"]),
                         _percent(cell["damping_error_median"]),
                         _percent(cell["damping_error_p90"]),
                         f"{cell['wrong']}/{row['runs']}", f"{cell['warned']}/{row['runs']}",
                         cell["silently_wrong"],
                         cell.get("silently_worse_than_n4sid", "-"),
                         _coverage(cell)])
    print(format_table(["SNR [dB]", "samples", "method", "freq err med [%]", "freq p90 [%]",
                        "damp err med [%]", "damp p90 [%]", "wrong", "warned", "silently wrong",
                        "silently > 1.5x N4SID", "95 % CI coverage f/z [%]"], rows))
    print(f"{len(results)} runs in {elapsed:.0f} s")
    for path in paths:
        print(f"wrote {path}")
    return 0
