"""Every PNG the project writes has units on its axes: each plot command's figure is drawn from
small inputs, caught at ``savefig``, and its axis labels read. A label that is a bare scene key
(``rig.floor_masses.1``) or carries no unit in brackets fails, as does an axis with data and no
label. The Monte Carlo figures also carry their targets, nominal values and title."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.figure
import numpy as np
import pytest

from stillframe.locations import SCENES_DIR

UNIT = re.compile(r"\[[^\]]+\]")
#: what a label says in place of a unit its source does not know
NOT_A_UNIT = ("unit not declared", "unit unknown")
BARE_KEY = re.compile(r"[A-Za-z_]\w*(\.\w+)+")


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> dict[str, matplotlib.figure.Figure]:
    """The figures saved while the test runs, by file name (nothing is drawn into the files
    ``stillframe.files`` opens for them, which have the path as their name)."""
    saved: dict[str, matplotlib.figure.Figure] = {}
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda fig, to, **_: saved.__setitem__(Path(to.name).name, fig))
    return saved


def unit_problems(fig: matplotlib.figure.Figure) -> list[str]:
    """What is wrong with a figure's axis labels ('' entries: none)."""
    problems = []
    has_xlabel = False
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        has_data = bool(ax.lines or ax.images or ax.patches or ax.collections)
        for which, label in (("x", ax.get_xlabel()), ("y", ax.get_ylabel())):
            has_xlabel |= which == "x" and bool(label)
            if not label:
                if which == "y" and has_data:
                    problems.append(f"an axis with data and no {which} label")
                continue
            if BARE_KEY.fullmatch(label.strip()):
                problems.append(f"{which} label is a bare key: {label!r}")
            elif not UNIT.search(label) or any(text in label for text in NOT_A_UNIT):
                problems.append(f"{which} label has no unit: {label!r}")
    if not has_xlabel:
        problems.append("no x label")
    return problems


def assert_units(figures: dict[str, matplotlib.figure.Figure], expected: int) -> None:
    assert len(figures) >= expected, sorted(figures)
    problems = {name: unit_problems(fig) for name, fig in figures.items()}
    assert not any(problems.values()), problems


def test_monte_carlo_plots(figures: dict, tmp_path: Path) -> None:
    from stillframe.studies.report import PlotContext, plot

    rng = np.random.default_rng(0)
    rows = [{"run": i, "status": "ok", "error": "", "rig.floor_masses.2": 0.814 * (1 + d),
             **{f"reduction_pct.{q}.{f}": 60 + 10 * rng.standard_normal()
                for q in ("displacement", "velocity") for f in (1, 2, 3)}}
            for i, d in enumerate(rng.uniform(-0.1, 0.1, 12))]
    context = PlotContext("lqg_mismatch", "closed-loop",
                          targets={"reduction_pct.displacement.1": 50.0},
                          nominal={"rig.floor_masses.2": 0.814})
    paths = plot(rows, ["rig.floor_masses.2"], tmp_path, context)
    assert [p.name for p in paths] == ["histograms.png", "vs_rig.floor_masses.2.png"]
    assert_units(figures, 2)
    scatter = figures["vs_rig.floor_masses.2.png"]
    first = scatter.axes[0]
    # named from the scene schema (doc "m1..m3 [kg]") and from the figure's pattern
    assert first.get_xlabel() == "m2 [kg] (rig.floor_masses.2)"
    assert first.get_ylabel() == "displacement reduction, floor 1 [%]"
    assert scatter.texts[0].get_text() == "lqg_mismatch: 12 runs (closed-loop)"   # suptitle
    # the nominal value as a vertical line and the target as a horizontal one
    xs = {tuple(line.get_xdata()) for line in first.lines}
    ys = {tuple(line.get_ydata()) for line in first.lines}
    assert (0.814, 0.814) in xs and (50.0, 50.0) in ys
    assert (50.0, 50.0) in {tuple(line.get_xdata()) for line in figures["histograms.png"].axes[0]
                            .lines}
    # a figure without a target has no target line
    assert not any(tuple(line.get_ydata()) == (50.0, 50.0) for line in scatter.axes[1].lines)


def test_demo_experiment_and_ph_plots(figures: dict, tmp_path: Path) -> None:
    from stillframe.app.commands.demo import plot_floors
    from stillframe.app.commands.ph import _crank_plot
    from stillframe.app.experiment_report import DESIGNS, QUANTITIES, plot_comparison
    from stillframe.config.scene import load_scene

    scene = load_scene(SCENES_DIR / "thesis_lqg.yaml")
    t = np.linspace(0.0, 1.0, 50)
    floors = np.zeros((50, 3))
    plot_floors(tmp_path / "floors.png", (t, floors), (t, floors), scene)
    histories = {}
    for name in DESIGNS:
        histories[name] = tmp_path / f"{name}.npz"
        np.savez(histories[name], fine_t=t, fine_floors=floors)
    result = SimpleNamespace(histories=histories, loop=scene)
    doc = {"scene": scene.name,
           "reduction_pct": {n: {q: [50.0, 60.0, 70.0] for q in QUANTITIES} for n in DESIGNS}}
    plot_comparison(tmp_path / "experiment.png", result, doc)
    angle = np.linspace(0.0, 1.0, 10)
    _crank_plot(str(tmp_path / "crank.png"),
                SimpleNamespace(crank_angle=angle, u_mid_over_l=angle, w_mid_over_l=angle))
    assert_units(figures, 3)


def test_bench_plots(figures: dict, tmp_path: Path) -> None:
    from stillframe.app.bench import fidelity as bench_fidelity
    from stillframe.app.bench import identify as bench_identify
    from stillframe.identification.sweep import METHODS

    point = {"scene": "s", "model": "lumped", "method": "midpoint", "cpu_per_s": 0.1,
             "error": 1e-3, "dt": 1e-3}
    bench_fidelity.plot({"scenes": ["s"], "points": [point], "pareto": {"s": [point]},
                         "reference": {"model": "fe", "method": "dop853", "dt": 1e-4}}, tmp_path)
    cell: dict[str, Any] = {key: 0.01 for key, _, _ in bench_identify.FIGURES}
    table = [{"snr_db": s, "samples": n, **{m: cell for m in METHODS}}
             for s in (40, 15) for n in (1024, 256)]
    bench_identify.heat_maps(table, tmp_path)
    assert_units(figures, 1 + len(METHODS) * len(bench_identify.FIGURES))


def test_adapt_timeline_plot(figures: dict, tmp_path: Path) -> None:
    from stillframe.app.adaptation_plot import plot_timeline

    t = np.linspace(0.0, 10.0, 50)
    results = {}
    for name in ("fixed", "adaptive", "oracle"):
        np.savez(tmp_path / f"{name}.npz", fine_t=t, fine_floors=np.zeros((50, 3)))
        results[name] = SimpleNamespace(history_file=tmp_path / f"{name}.npz", evaluation={})
    results["adaptive"].evaluation = {"adaptation": {
        "updates": [{"t": 4.0 + i, "frequency_hz": [1.1, 1.98, 5.79, 8.82 - 0.1 * i],
                     "statistic": None if i < 2 else 3.0 * i} for i in range(5)],
        "events": [{"kind": "detection", "t": 8.0, "reference_hz": [1.1, 1.98, 5.79, 8.82],
                    "reference_std_hz": [0.01, 0.01, 0.01, 0.01]}]}}
    doc = {"scene": "s", "adaptation": {"change_at_s": 6.0, "detected_at_s": 8.0,
                                        "true_hz": [1.1, 1.91, 5.76, 8.07]},
           "details": {"handover_s": 9.0, "threshold": 40.0}}
    plot_timeline(tmp_path / "timeline.png", doc, results)
    assert_units(figures, 1)


def test_the_checker_refuses_a_bare_key_and_a_missing_unit() -> None:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    ax.set_xlabel("rig.floor_masses.1")
    ax.set_ylabel("command")
    assert unit_problems(fig) == ["x label is a bare key: 'rig.floor_masses.1'",
                                  "y label has no unit: 'command'"]
    ax.set_ylabel("input weight [unit not declared] (controller.input_weight)")
    assert unit_problems(fig)[1].startswith("y label has no unit")
    plt.close(fig)


def test_the_dashboard_axes_have_units() -> None:
    """The live dashboard (Plotly, in the browser): every chart's axis titles come from
    ``CHARTS`` with units, the command's left axis is N·m."""
    from stillframe.monitor.dashboard import CHARTS, TIME_AXIS

    for title, left, right in CHARTS.values():
        for label in (left, right, TIME_AXIS):
            assert label is None or UNIT.search(label), (title, label)
    assert CHARTS["command"][1] == "torque [N·m]"


def test_identification_plots(figures: dict, tmp_path: Path) -> None:
    """The plots of ``identify --plots`` (its helpers, on synthetic data)."""
    from stillframe.identification import plots

    f = np.linspace(0.1, 10.0, 20)
    plots.hankel_singular_values(np.array([1.0, 0.5, 0.1, 0.01]), 2, tmp_path / "h.png")
    plots.stabilization_diagram([2, 4], [np.array([1.0]), np.array([1.0, 2.0])],
                                [np.array([True]), np.array([True, False])], 2,
                                tmp_path / "s.png", nyquist_hz=5.0)
    h = np.ones((20, 2, 1), dtype=complex)
    plots.frf(f, h, np.ones((20, 2, 1)), h, ["u"], ["y1", "y2"], tmp_path / "frf.png",
              input_units=["N"], output_units=["m/s^2", "m/s^2"], segments=4)
    plots.mode_shapes(np.array([1.0, 2.0]), np.array([0.02, 0.03]), np.ones((2, 2), complex),
                      ["y1", "y2"], tmp_path / "m.png")
    assert_units(figures, 4)


def test_identify_daisy_plots(figures: dict, tmp_path: Path) -> None:
    """The plots of ``identify-daisy --plots`` (the same helpers as the command, on synthetic
    data): DaISy gives no units for its outputs, so the validation plot shows each output over
    the standard deviation of its measured values."""
    from stillframe.identification import plots

    t = np.arange(200) / 1024
    measured = np.column_stack([np.sin(40 * t), 3 * np.cos(60 * t)])
    plots.validation(t, measured, {"n4sid": 0.9 * measured}, ["y1", "y14"],
                     tmp_path / "daisy_validation.png", span=0.1)
    plots.mode_comparison({"n4sid": [{"frequency_hz": 229.0, "damping_ratio": 0.002,
                                      "peak": 1.0}]}, tmp_path / "daisy_modes.png")
    assert_units(figures, 2)
    lines = figures["daisy_validation.png"].axes[1].lines
    np.testing.assert_allclose(lines[0].get_ydata(), measured[t <= t[0] + 0.1, 1]
                               / measured[:, 1].std())
