"""Issue 27 must show 7: the identification figures carry |H|'s unit, an honest coherence panel
and integer order ticks. The figures are inspected before they are saved (``_save`` captured)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from stillframe.bags.channels import Channel
from stillframe.identification import plots
from stillframe.identification.frf import h1_frf, segment_length, welch_segments


@pytest.fixture
def captured(monkeypatch: pytest.MonkeyPatch) -> list:
    figures: list = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figures.append(fig) or path)
    yield figures
    for fig in figures:
        plots.plt.close(fig)


def test_channel_units_follow_rep_103() -> None:
    assert Channel("/frame/floor1/imu", "linear_acceleration.x").unit == "m/s²"
    assert Channel("/frame/excitation/wrench", "wrench.force.x").unit == "N"
    assert Channel("/frame/pendulum/torque_cmd", "wrench.torque.z").unit == "N m"
    assert Channel("/frame/pendulum/joint_states", "position[0]").unit == "rad"
    assert Channel("/x", "data").unit is None
    assert plots.magnitude_unit("m/s²", "N") == "(m/s²)/N"
    assert plots.magnitude_unit("rad", "N m") == "rad/(N m)"
    assert plots.magnitude_unit(None, "N") == "unit unknown"


@pytest.mark.parametrize("samples", [64, 300, 1024, 4096])
def test_welch_segments_are_scipys(samples: int) -> None:
    """The count against scipy's STFT with the same half overlap and no padding; the chosen
    length gives at least 8 segments where the record allows 8 of 8 samples."""
    nperseg = segment_length(samples)
    _, t, _ = signal.stft(np.ones(samples), nperseg=nperseg, noverlap=nperseg // 2,
                          boundary=None, padded=False)
    assert welch_segments(samples, nperseg) == t.size
    assert t.size >= 8 and nperseg <= 256


def test_frf_magnitude_has_its_unit_and_coherence_its_segments(captured: list) -> None:
    rng = np.random.default_rng(0)
    u = rng.standard_normal((1024, 1))
    y = signal.lfilter([1.0], [1.0, -0.9], u[:, 0])[:, None] + 0.3 * rng.standard_normal((1024, 1))
    measured = h1_frf(u, y, 0.01, nperseg=segment_length(1024))
    plots.frf(measured.frequency_hz, measured.H, measured.coherence, measured.H, ["u"], ["y"],
              "frf.png", input_units=["N"], output_units=["m/s²"], segments=measured.segments)
    mag, _, coh = captured[0].axes[:3]
    assert mag.get_ylabel() == "|H| [(m/s²)/N]"
    assert coh.get_ylabel() == f"coherence, {measured.segments} seg. [-]"
    shown = coh.lines[0].get_ydata()
    assert shown.min() < 0.9  # the noise shows: not flat at 1


def test_one_segment_leaves_the_coherence_out_with_a_note(captured: list) -> None:
    rng = np.random.default_rng(1)
    u, y = rng.standard_normal((64, 1)), rng.standard_normal((64, 1))
    single = h1_frf(u, y, 0.01, nperseg=64)
    assert single.segments == 1 and np.allclose(single.coherence, 1.0)  # why it is left out
    plots.frf(single.frequency_hz, single.H, single.coherence, single.H, ["u"], ["y"], "f.png",
              segments=single.segments)
    coh = captured[0].axes[2]
    assert not coh.lines and "left out" in coh.texts[0].get_text()


def test_order_axes_have_integer_ticks(captured: list) -> None:
    orders = [2, 4, 6, 8]
    plots.stabilization_diagram(orders, [np.array([1.0 + k]) for k in range(4)],
                                [np.array([True])] * 4, 6, "s.png")
    plots.hankel_singular_values(np.logspace(0, -5, 7), 4, "h.png")
    stab, hankel = captured[0].axes[0], captured[1].axes[0]
    captured[0].canvas.draw()
    captured[1].canvas.draw()
    for ticks in (stab.get_yticks(), hankel.get_xticks()):
        assert np.all(ticks == np.round(ticks)), ticks


def test_every_identification_figure_has_units(monkeypatch: pytest.MonkeyPatch,
                                               tmp_path) -> None:
    """The checker of tests/unit/app/test_plot_units.py on identify's and ssi-cov's figures."""
    import matplotlib.figure

    from stillframe.bags.channels import Record
    from stillframe.identification.pipeline import identify
    from stillframe.identification.ssi_cov import identify_output_only
    from stillframe.identification.sweep import shear_building, simulate
    from tests.unit.app.test_plot_units import unit_problems

    saved: dict = {}
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda fig, path, **_: saved.__setitem__(str(path), fig))
    rec = simulate(shear_building(6), 1024, 40.0, 6)
    record = Record(bag="b", inputs=(Channel("/frame/excitation/wrench", "wrench.force.x"),),
                    outputs=tuple(Channel(f"/frame/floor{i}/imu", "linear_acceleration.x")
                                  for i in (1, 2, 3)),
                    t=np.arange(1024) * rec.dt, u=rec.u, y=rec.y, dt=rec.dt, start_ns=0)
    plots.identification_plots(identify(rec.u, rec.y, rec.dt, refine=False), record,
                               tmp_path)
    plots.output_only_plots(identify_output_only(rec.y, rec.dt, 6), record, tmp_path / "o")
    assert len(saved) == 8
    problems = {name: unit_problems(fig) for name, fig in saved.items()}
    assert not any(problems.values()), problems
