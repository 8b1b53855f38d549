"""The experiment's results (:mod:`stillframe.app.experiment`): identified against true M, K, R,
the reductions of both designs per floor and their ratio, as a JSON document, terminal tables
and a PNG.

Matrix errors: per entry, ``(identified − true) / |true|`` for the entries that are not zero in
the true matrix; per matrix, ``‖identified − true‖_F / ‖true‖_F`` (which also counts entries that
should be zero). The ratio of reductions is identified design over true design, per floor.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.experiment import ExperimentResult
from stillframe.files import save_figure
from stillframe.text_table import format_table

RATIO_GOAL = 0.9
QUANTITIES = ("displacement", "velocity")
DESIGNS = ("true_design", "identified_design")


def matrix_errors(identified: np.ndarray, true: np.ndarray) -> dict[str, Any]:
    """Entry-wise relative errors (None where the true entry is zero) and the Frobenius error."""
    nonzero = np.abs(true) > 1e-12 * np.max(np.abs(true))
    entries = np.where(nonzero, (identified - true) / np.where(nonzero, np.abs(true), 1.0), np.nan)
    return {"entry": [[None if np.isnan(v) else float(v) for v in row] for row in entries],
            "max_entry": float(np.nanmax(np.abs(entries))),
            "frobenius": float(np.linalg.norm(identified - true) / np.linalg.norm(true))}


def ratios(result: ExperimentResult) -> dict[str, list[float]]:
    red = {d: result.evaluation[d]["reduction_pct"] for d in DESIGNS}
    return {q: (np.asarray(red["identified_design"][q]) / np.asarray(red["true_design"][q])
                ).tolist() for q in QUANTITIES}


def document(result: ExperimentResult) -> dict[str, Any]:
    """Everything the command prints, as one JSON-serialisable dict."""
    ident = result.identified
    s = ident.structure
    physical: dict[str, Any] = {
        "identified": {"M": s.M.tolist(), "K": s.K.tolist(), "R": s.R.tolist()},
        "mkr_raw": {"M": ident.raw.M.tolist(), "K": ident.raw.K.tolist(),
                    "R": ident.raw.R.tolist()},
        "pendulum_apparent_mass": ident.pendulum_mass,
        "rayleigh_alpha": ident.rayleigh_alpha, "rayleigh_beta": ident.rayleigh_beta,
        "true": None, "relative_error": None,
    }
    if result.true_structure is not None:
        physical["true"] = {k: v.tolist() for k, v in result.true_structure.items()}
        physical["relative_error"] = {k: matrix_errors(getattr(s, k), v)
                                      for k, v in result.true_structure.items()}
    ratio = ratios(result)
    return {
        "scene": result.scene.name,
        "plant": result.loop.plant.model if result.loop.plant.model == "file"
        else result.loop.model.type,
        "identification": {
            "samples": result.samples, "dt": result.dt, "order": ident.ident.order,
            "method": ident.ident.method,
            "frequency_hz": ident.ident.modes.frequency_hz.tolist(),
            "damping_ratio": ident.ident.modes.damping_ratio.tolist(),
            "warnings": list(ident.warnings),
        },
        "physical": physical,
        "reduction_pct": {d: result.evaluation[d]["reduction_pct"] for d in DESIGNS},
        "peak_command": {d: result.evaluation[d]["peak_command"] for d in DESIGNS},
        "ratio": ratio,
        "goal": {"ratio_min": RATIO_GOAL,
                 "met": bool(all(min(v) >= RATIO_GOAL for v in ratio.values()))},
        "files": result.files,
    }


def physical_table(doc: dict[str, Any]) -> str:
    """One row per upper-triangle entry of M, K, R: identified, true, relative error."""
    p = doc["physical"]
    rows = []
    for key, unit in (("M", "kg"), ("K", "N/m"), ("R", "N s/m")):
        ident = np.asarray(p["identified"][key])
        true = None if p["true"] is None else np.asarray(p["true"][key])
        for i in range(3):
            for j in range(i, 3):
                err = None if true is None else p["relative_error"][key]["entry"][i][j]
                rows.append([f"{key}[{i + 1},{j + 1}] [{unit}]", f"{ident[i, j]:.5g}",
                             "-" if true is None else f"{true[i, j]:.5g}",
                             "-" if err is None else f"{100 * err:+.2f}"])
        if true is not None:
            rows.append([f"{key}: |error|_F / |true|_F", "", "",
                         f"{100 * p['relative_error'][key]['frobenius']:.2f}"])
    return format_table(["entry", "identified", "true", "error %"], rows)


def reduction_table(doc: dict[str, Any]) -> str:
    """Floors as rows: the reductions with each design and identified / true."""
    red, ratio = doc["reduction_pct"], doc["ratio"]
    rows = [[f"floor {i + 1}"]
            + [v for q in QUANTITIES for v in (f"{red['true_design'][q][i]:.2f}",
                                               f"{red['identified_design'][q][i]:.2f}",
                                               f"{ratio[q][i]:.3f}")]
            for i in range(3)]
    return format_table(["", "x red. % (true)", "x red. % (ident.)", "x ratio",
                         "v red. % (true)", "v red. % (ident.)", "v ratio"], rows)


def print_report(doc: dict[str, Any]) -> None:
    ident = doc["identification"]
    freqs = ", ".join(f"{f:.4f}" for f in ident["frequency_hz"])
    zetas = ", ".join(f"{z:.4f}" for z in ident["damping_ratio"])
    print(f"scene {doc['scene']} (plant {doc['plant']}): {ident['samples']} samples at "
          f"{1 / ident['dt']:g} Hz, {ident['method']} order {ident['order']}; modes {freqs} Hz, "
          f"damping ratios {zetas}")
    p = doc["physical"]
    print(f"identified structure: MKR M with the pendulum's apparent mass "
          f"{p['pendulum_apparent_mass']:.4g} kg taken off floor 3; R = alpha M + beta K, "
          f"alpha = {p['rayleigh_alpha']:.4g} 1/s, beta = {p['rayleigh_beta']:.4g} s"
          + ("" if p["true"] is not None else "; the plant has no 3x3 true M, K, R"))
    print(physical_table(doc))
    print()
    print("steady-state peak reductions, LQG designed on the true and on the identified model:")
    print(reduction_table(doc))
    goal = doc["goal"]
    print(f"{'met' if goal['met'] else 'MISSED'}: identified design >= {goal['ratio_min']:g} of "
          "the true-model design's reductions on every floor")


def plot_comparison(path: Path, result: ExperimentResult, doc: dict[str, Any]) -> None:
    """Floor displacements with each design (one panel per floor) and the reductions (bars)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(4, 1, figsize=(9, 10), constrained_layout=True,
                             gridspec_kw={"height_ratios": [1, 1, 1, 1.2]})
    styles = {"true_design": ("0.45", "designed on the true model"),
              "identified_design": ("C0", "designed on the identified model")}
    widths = {"true_design": 1.8, "identified_design": 0.5}
    for name in DESIGNS:
        with np.load(result.histories[name]) as data:
            t, floors = data["fine_t"], data["fine_floors"]
        color, label = styles[name]
        for i in range(3):
            axes[i].plot(t, 1e3 * floors[:, i], color=color, lw=widths[name], label=label)
    for i in range(3):
        axes[i].axvline(result.loop.controller.start, color="C3", ls="--", lw=0.8)
        axes[i].set_ylabel(f"x{i + 1} [mm]")
    axes[0].legend(loc="upper left", ncol=2, fontsize="small")
    axes[0].set_title(f"{doc['scene']}: LQG from {result.loop.controller.start:g} s (dashed)")
    axes[2].set_xlabel("t [s]")
    width = 0.2
    x = np.arange(3)
    for k, (q, name) in enumerate((q, n) for q in QUANTITIES for n in DESIGNS):
        values = doc["reduction_pct"][name][q]
        axes[3].bar(x + (k - 1.5) * width, values, width, color=styles[name][0],
                    alpha=1.0 if q == "displacement" else 0.55,
                    label=f"{q[0]}: {styles[name][1]}")
    axes[3].set_xticks(x, [f"floor {i + 1}" for i in range(3)])
    axes[3].set_ylabel("peak reduction [%]")
    axes[3].legend(fontsize="small", ncol=2, loc="lower right")
    save_figure(fig, path, dpi=110)
    plt.close(fig)
