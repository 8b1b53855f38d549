"""The timeline of one ``stillframe adapt`` run as a figure (docs/adaptation.md): the adaptive
loop's tracked frequencies with the spread of its reference, the CUSUM statistic against its
threshold, and each floor's displacement (its RMS over short windows) under the fixed, the
adaptive and the oracle controller, with the change, the detection and the hand-over marked on
every panel."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.launcher import LaunchResult
from stillframe.files import save_figure

#: the reference's spread drawn around each update: ± this many of its standard deviations
SPREAD = 1.96
#: the floors' displacements are drawn as their RMS over windows this long [s]
RMS_S = 2.0


def moving_rms(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The RMS of ``x`` over consecutive windows of :data:`RMS_S`, at each window's end."""
    edges = np.arange(t[0], t[-1] + RMS_S, RMS_S)
    which = np.digitize(t, edges) - 1
    sums = np.bincount(which, weights=x * x, minlength=edges.size)
    counts = np.bincount(which, minlength=edges.size)
    keep = counts > 0
    return edges[keep] + RMS_S, np.sqrt(sums[keep] / counts[keep])


def plot_timeline(path: Path, doc: dict[str, Any], results: dict[str, LaunchResult]) -> None:
    """Draw the timeline the module's docstring describes for the adaptation document ``doc`` and
    the three launches' ``results`` (keyed ``fixed``, ``adaptive``, ``oracle``) and save it to
    ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a, d = doc["adaptation"], doc["details"]
    record = results["adaptive"].evaluation.get("adaptation", {})
    updates = [u for u in record.get("updates", []) if u["frequency_hz"]]
    detections = [e for e in record.get("events", []) if e["kind"] == "detection"]
    fig, axes = plt.subplots(5, 1, figsize=(10, 12), sharex=True, constrained_layout=True)
    ax = axes[0]
    before = np.array(detections[0]["reference_hz"]) if detections else None
    if updates and before is not None:
        t = np.array([u["t"] for u in updates])
        modes = min(len(u["frequency_hz"]) for u in updates)
        f = np.array([u["frequency_hz"][:modes] for u in updates])
        spread = SPREAD * np.array(detections[0]["reference_std_hz"][:modes])
        for i in range(modes):
            ax.errorbar(t, 100 * (f[:, i] / before[i] - 1), yerr=100 * spread[i] / before[i],
                        fmt="o", ms=3, capsize=2, label=f"mode {i + 1} ({before[i]:.3g} Hz)")
            ax.axhline(100 * (a["true_hz"][i] / before[i] - 1), ls=":", lw=0.8,
                       color=f"C{i}")
        ax.legend(loc="lower left", fontsize=8, ncol=4)
    ax.set_ylabel("frequency − reference [%]")
    ax.set_title(f"{doc['scene']}: tracked frequencies (bars: ± {SPREAD:g} σ of the reference "
                 "updates; dotted: the true model after the change)", fontsize=9)
    ax = axes[1]
    stat = [(u["t"], np.nan if u.get("statistic") is None else max(u["statistic"], 1e-2))
            for u in record.get("updates", [])]
    if stat:
        ts, gs = zip(*stat, strict=True)
        ax.semilogy(ts, gs, ".-", label="largest CUSUM statistic (none while a reference "
                                       "is set; 0 drawn at 0.01)")
        ax.axhline(d["threshold"], color="k", ls="--", lw=0.8, label="threshold")
        ax.legend(loc="upper left", fontsize=8)
    ax.set_ylabel("CUSUM statistic [σ]")
    for floor in range(3):
        ax = axes[2 + floor]
        for name, color in (("fixed", "0.5"), ("adaptive", "C3"), ("oracle", "C2")):
            with np.load(results[name].history_file) as hist:
                t, rms = moving_rms(hist["fine_t"], hist["fine_floors"][:, floor])
            ax.plot(t, 1e3 * rms, color=color, lw=1, label=name)
        ax.set_ylabel(f"x{floor + 1}, RMS over {RMS_S:g} s [mm]")
        ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    for ax in axes:
        ax.axvline(a["change_at_s"], color="r", lw=1, label="_change")
        if a["detected_at_s"] is not None:
            ax.axvline(a["detected_at_s"], color="orange", lw=1)
        if d["handover_s"] is not None:
            ax.axvline(d["handover_s"], color="g", lw=1)
    axes[0].text(0.99, 0.95, "red: change, orange: detection, green: hand-over",
                 transform=axes[0].transAxes, ha="right", va="top", fontsize=8)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
