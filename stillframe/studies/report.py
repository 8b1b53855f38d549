"""The report of a study: the run table (CSV), quantiles of the headline figures with the worst
run, the fractions that met the targets or went unstable, and PNG plots (docs/montecarlo.md)."""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stillframe.files import open_output, save_figure

QUANTILES: tuple[float, ...] = (0.05, 0.25, 0.5, 0.75, 0.95)
HEADLINES: dict[str, tuple[tuple[str, ...], str]] = {
    "closed-loop": (("reduction_pct.",), "min"),
    "simulate": (("peak_displacement_m.", "peak_acceleration_m_s2."), "max"),
    "identify": (("frequency_error", "damping_error"), "max"),
}
"""Per kind of run: the column prefixes summarised and which end is the worst case."""


def write_table(rows: Sequence[dict[str, Any]], path: Path) -> Path:
    """One CSV row per run; columns in first-seen order; floats as their shortest exact text."""
    columns = list(dict.fromkeys(k for r in rows for k in r))
    path.parent.mkdir(parents=True, exist_ok=True)
    with io.TextIOWrapper(open_output(path, what="run table"), encoding="utf-8",
                          newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns)
        writer.writeheader()
        writer.writerows([{k: repr(v) if isinstance(v, float) else v for k, v in r.items()}
                          for r in rows])
    return path


def headline_columns(rows: Sequence[dict[str, Any]], what: str) -> list[str]:
    prefixes = HEADLINES[what][0]
    columns = dict.fromkeys(k for r in rows for k in r if k.startswith(prefixes))
    return [c for c in columns if all(isinstance(r.get(c, 0.0), int | float) for r in rows)]


def quantiles(rows: Sequence[dict[str, Any]], what: str) -> dict[str, dict[str, Any]]:
    """Per headline column, over the runs that finished: quantiles, mean, worst value and run."""
    worst_is_min = HEADLINES[what][1] == "min"
    out = {}
    for column in headline_columns(rows, what):
        pairs = [(r[column], r["run"]) for r in rows
                 if r["status"] == "ok" and math.isfinite(r.get(column, math.nan))]
        if not pairs:
            continue
        values = np.array([v for v, _ in pairs])
        worst = (min if worst_is_min else max)(pairs)
        out[column] = {f"q{round(100 * q):02d}": float(np.quantile(values, q))
                       for q in QUANTILES} | {
            "mean": float(values.mean()), "worst": float(worst[0]), "worst_run": worst[1],
            "runs": len(pairs)}
    return out


def fractions(rows: Sequence[dict[str, Any]],
              met: Callable[[dict[str, Any]], bool] | None) -> dict[str, float | None]:
    """Fractions of all runs that met the targets (None without targets), went unstable or
    failed."""
    n = max(len(rows), 1)
    return {
        "met_targets": (sum(r["status"] == "ok" and met(r) for r in rows) / n
                        if met is not None else None),
        "unstable": sum(r["status"] == "unstable" for r in rows) / n,
        "failed": sum(r["status"] == "failed" for r in rows) / n,
    }


#: the figures of a run as the table names them (``reduction_pct.displacement.1``): a label
#: with its unit, from the column's pattern (the numbers are 1-based floors or modes)
FIGURE_LABELS: tuple[tuple[re.Pattern[str], str], ...] = tuple(
    (re.compile(pattern), label) for pattern, label in (
        (r"reduction_pct\.(\w+)\.(\d)", "{0} reduction, floor {1} [%]"),
        (r"peak_displacement_m\.(\d)", "peak displacement, floor {0} [m]"),
        (r"peak_acceleration_m_s2\.(\d)", "peak acceleration, floor {0} [m/s²]"),
        (r"(frequency|damping)_error", "worst relative {0} error [-]"),
    ))


def figure_label(column: str) -> str:
    """``displacement reduction, floor 1 [%]`` for ``reduction_pct.displacement.1``."""
    for pattern, label in FIGURE_LABELS:
        if match := pattern.fullmatch(column):
            return label.format(*match.groups())
    return column


@dataclass(frozen=True)
class PlotContext:
    """What the plots say besides the runs: the scene, the targets a figure must reach
    (column -> value) and the nominal value of each varied key (column -> value)."""

    scene: str
    what: str
    targets: dict[str, float] = field(default_factory=dict)
    nominal: dict[str, float] = field(default_factory=dict)

    def title(self, runs: int) -> str:
        return f"{self.scene}: {runs} runs ({self.what})"


def plot(rows: Sequence[dict[str, Any]], varied: Sequence[str], directory: Path,
         context: PlotContext) -> list[Path]:
    """Histograms of the headline figures with their targets; each headline figure against each
    varied key with the nominal value marked. Axes are labelled from the scene schema
    (:func:`stillframe.config.labels.key_label`) and :data:`FIGURE_LABELS`, with units."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    from stillframe.config.labels import key_label

    ok = [r for r in rows if r["status"] == "ok"]
    columns = headline_columns(ok, context.what)
    if not ok or not columns:
        return []
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    cols = min(3, len(columns))
    grid = (math.ceil(len(columns) / cols), cols)

    def target(ax: Any, column: str, vertical: bool) -> None:
        if column in context.targets:
            line = ax.axvline if vertical else ax.axhline
            line(context.targets[column], color="C3", ls="--", lw=1,
                 label=f"target {context.targets[column]:g}")
            ax.legend(fontsize=7)

    def save(fig: Any, name: str) -> None:
        fig.suptitle(context.title(len(ok)), fontsize=10)
        fig.tight_layout()
        paths.append(directory / name)
        save_figure(fig, paths[-1], dpi=100)
        plt.close(fig)

    fig, axes = plt.subplots(*grid, figsize=(4 * cols, 3 * grid[0]), squeeze=False)
    for ax, column in zip(axes.flat, columns, strict=False):
        ax.hist([r[column] for r in ok], bins="auto", color="C0")
        ax.set_xlabel(figure_label(column), fontsize=8)
        ax.set_ylabel("runs [-]", fontsize=8)
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))   # runs are counted
        target(ax, column, vertical=True)
    for ax in list(axes.flat)[len(columns):]:
        ax.set_visible(False)
    save(fig, "histograms.png")
    for key in varied:
        if not all(isinstance(r.get(key), int | float) for r in ok):
            continue
        fig, axes = plt.subplots(*grid, figsize=(4 * cols, 3 * grid[0]), squeeze=False)
        for ax, column in zip(axes.flat, columns, strict=False):
            ax.plot([r[key] for r in ok], [r[column] for r in ok], ".", ms=3)
            if key in context.nominal:
                ax.axvline(context.nominal[key], color="k", ls=":", lw=1,
                           label=f"nominal {context.nominal[key]:g}")
                ax.legend(fontsize=7)
            ax.set_xlabel(key_label(key), fontsize=8)
            ax.set_ylabel(figure_label(column), fontsize=8)
            target(ax, column, vertical=False)
        for ax in list(axes.flat)[len(columns):]:
            ax.set_visible(False)
        save(fig, f"vs_{key}.png")
    return paths
