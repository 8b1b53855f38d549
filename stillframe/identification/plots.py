"""PNG figures of an identification: Hankel singular values, stabilization diagram, FRF (H1 with
coherence, identified model overlaid) and mode shapes. matplotlib with the Agg backend; every
function takes plain arrays, writes one file and returns its path."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import MaxNLocator

from stillframe.bags.channels import Record
from stillframe.files import save_figure
from stillframe.identification.frf import h1_frf, model_frf, segment_length
from stillframe.identification.pipeline import Identification
from stillframe.identification.ssi_cov import OutputOnlyIdentification
from stillframe.identification.stabilization import stabilization_diagram as stabilization_rows


def _save(fig: plt.Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def _channel_key(fig: plt.Figure, entries: list[str]) -> None:
    """Lay the figure out, leaving a strip at the bottom that says which channel is which."""
    rows = (len(entries) + 1) // 2
    fig.tight_layout(rect=(0, 0.02 + 0.025 * rows, 1, 1))
    for k, entry in enumerate(entries):
        fig.text(0.01 + 0.5 * (k % 2), 0.01 + 0.025 * (rows - 1 - k // 2), entry, fontsize=7)


def hankel_singular_values(singular_values: np.ndarray, order: int, path: Path,
                           title: str = "Hankel singular values") -> Path:
    """Normalised singular values on a log scale, the chosen order marked."""
    s = np.asarray(singular_values, dtype=float)
    s = s[s > 0] / s[0]
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.semilogy(np.arange(1, s.size + 1), s, "o-", ms=3)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.axvline(order + 0.5, color="C3", ls="--", label=f"order {order}")
    ax.set_xlabel("index [-]")
    ax.set_ylabel(r"$\sigma_i / \sigma_1$ [-]")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return _save(fig, path)


def stabilization_diagram(orders: Sequence[int], frequencies_hz: Sequence[np.ndarray],
                          stable: Sequence[np.ndarray], chosen: int, path: Path,
                          nyquist_hz: float | None = None,
                          frequency_ci_hz: np.ndarray | None = None) -> Path:
    """Poles' frequencies against model order; stable ones filled, the chosen order marked;
    with ``frequency_ci_hz (modes, 2)`` the chosen model's 95 % intervals as bars on its line."""
    fig, ax = plt.subplots(figsize=(8, 5))
    if frequency_ci_hz is not None:
        ci = np.asarray(frequency_ci_hz, dtype=float)
        ax.hlines(np.full(len(ci), chosen), ci[:, 0], ci[:, 1], color="C1", lw=6, alpha=0.6,
                  label="95 % interval (chosen model)")
    for n, f, ok in zip(orders, frequencies_hz, stable, strict=True):
        f, ok = np.asarray(f), np.asarray(ok, dtype=bool)
        ax.plot(f[ok], np.full(ok.sum(), n), "o", color="C0", ms=4)
        ax.plot(f[~ok], np.full((~ok).sum(), n), "x", color="C7", ms=4)
    ax.axhline(chosen, color="C3", ls="--", lw=1)
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.plot([], [], "o", color="C0", label="stable (frequency, damping, MAC)")
    ax.plot([], [], "x", color="C7", label="not stable")
    ax.plot([], [], "--", color="C3", label=f"chosen order {chosen}")
    if nyquist_hz:
        ax.set_xlim(0, nyquist_hz)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("model order [-]")
    ax.set_title("Stabilization diagram")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncols=3, fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def magnitude_unit(output_unit: str | None, input_unit: str | None) -> str:
    """The unit of |H| from output to input, ``(m/s²)/N``; ``unit unknown`` when either is."""
    if output_unit is None or input_unit is None:
        return "unit unknown"
    def wrap(unit: str) -> str:
        return f"({unit})" if any(c in unit for c in " /") else unit
    return f"{wrap(output_unit)}/{wrap(input_unit)}"


def frf(freq_hz: np.ndarray, h1: np.ndarray, coherence: np.ndarray | None, model: np.ndarray,
        input_names: Sequence[str], output_names: Sequence[str], path: Path, *,
        input_units: Sequence[str | None] | None = None,
        output_units: Sequence[str | None] | None = None, segments: int = 0) -> Path:
    """Magnitude (with its unit, output unit over input unit) and phase per input-output pair and
    each output's (multiple) coherence from ``segments`` Welch segments; ``h1`` and ``model`` are
    (frequencies, outputs, inputs), ``coherence`` (frequencies, outputs). With fewer than two
    segments (or ``coherence`` None) the coherence row says why it is left out: one segment's
    coherence is 1 at every frequency whatever the noise."""
    p, m = h1.shape[1:]
    input_units = input_units or [None] * m
    output_units = output_units or [None] * p
    show_coherence = coherence is not None and segments >= 2
    fig, axes = plt.subplots(3, p * m, figsize=(4 * p * m, 8), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": [3, 2, 1]})
    for j in range(m):
        for i in range(p):
            col = j * p + i
            mag, ph, coh = axes[:, col]
            mag.semilogy(freq_hz, np.abs(h1[:, i, j]), color="C0", lw=1, label="H1 estimate")
            mag.semilogy(freq_hz, np.abs(model[:, i, j]), color="C3", lw=1, label="model")
            ph.plot(freq_hz, np.degrees(np.angle(h1[:, i, j])), color="C0", lw=1)
            ph.plot(freq_hz, np.degrees(np.angle(model[:, i, j])), color="C3", lw=1)
            if show_coherence:
                coh.plot(freq_hz, coherence[:, i], color="C2", lw=1)
            else:
                coh.text(0.5, 0.5, "coherence left out: a single record segment gives 1 at "
                         "every frequency", ha="center", va="center", fontsize=7,
                         transform=coh.transAxes, wrap=True)
            mag.set_title(f"y{i + 1} / u{j + 1}", fontsize=9)
            mag.set_ylabel(f"|H| [{magnitude_unit(output_units[i], input_units[j])}]",
                           fontsize=8)
            ph.set_ylabel("phase [deg]", fontsize=8)
            coh.set_ylabel(f"coherence, {segments} seg. [-]" if show_coherence
                           else "coherence [-]", fontsize=8)
            coh.set_ylim(0, 1.05)
            coh.set_xlabel("frequency [Hz]")
            for ax in (mag, ph, coh):
                ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    _channel_key(fig, [*(f"u{j + 1} = {n}" for j, n in enumerate(input_names)),
                       *(f"y{i + 1} = {n}" for i, n in enumerate(output_names))])
    return _save(fig, path)


def mode_shapes(frequency_hz: np.ndarray, damping_ratio: np.ndarray, shapes: np.ndarray,
                output_names: Sequence[str], path: Path) -> Path:
    """Each complex shape (outputs, modes) as magnitude (top) and phase (bottom) per sensor."""
    modes = shapes.shape[1]
    x = np.arange(shapes.shape[0])
    fig, axes = plt.subplots(2, modes, figsize=(3.2 * max(modes, 1), 5.5), squeeze=False,
                             sharey="row")
    for k in range(modes):
        mag, ph = axes[:, k]
        mag.bar(x, np.abs(shapes[:, k]), color="C0")
        ph.bar(x, np.degrees(np.angle(shapes[:, k])), color="C1")
        mag.set_title(f"{frequency_hz[k]:.4g} Hz, ζ {damping_ratio[k]:.3g}", fontsize=9)
        ph.set_ylim(-185, 185)
        ph.set_xticks(x, [f"y{i + 1}" for i in x])
        ph.set_xlabel("sensor [-]")
        mag.set_ylabel("magnitude [normalised]")
        ph.set_ylabel("phase [deg]")
        mag.set_xticks(x, [])
        for ax in (mag, ph):
            ax.grid(True, alpha=0.3)
    _channel_key(fig, [f"y{i + 1} = {n}" for i, n in enumerate(output_names)])
    return _save(fig, path)


def validation(t: np.ndarray, measured: np.ndarray, simulated: dict[str, np.ndarray],
               names: Sequence[str], path: Path, span: float | None = None,
               units: Sequence[str] | None = None) -> Path:
    """Measured outputs beside each model's simulated outputs (first ``span`` seconds), in the
    outputs' ``units``; without units (a record that does not give them, as DaISy's), each
    output divided by the standard deviation of its measured values, a unit of its own."""
    count = len(names)
    keep = t <= t[0] + span if span else np.ones(t.size, dtype=bool)
    scale = np.ones(count) if units else measured.std(axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    labels = ([f"{n} [{u}]" for n, u in zip(names, units, strict=True)] if units
              else [f"{n} / std({n}) [-]" for n in names])
    fig, axes = plt.subplots(count, 1, figsize=(9, 1.8 * count + 1), sharex=True, squeeze=False)
    for i, ax in enumerate(axes[:, 0]):
        ax.plot(t[keep], measured[keep, i] / scale[i], color="k", lw=1, label="measured")
        for c, (label, y) in enumerate(simulated.items()):
            ax.plot(t[keep], y[keep, i] / scale[i], color=f"C{c}", lw=0.8, label=label)
        ax.set_ylabel(labels[i], fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=8, ncols=len(simulated) + 1)
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    return _save(fig, path)


def identification_plots(ident: Identification, record: Record, directory: str | Path,
                         nperseg: int | None = None) -> list[Path]:
    """All figures of one identification from a bag record, written into ``directory``:
    Hankel singular values, stabilization diagram (even orders up to twice the chosen order,
    at least 20), H1 FRF with the model overlaid (Welch segments of ``nperseg`` samples, default
    :func:`~stillframe.identification.frf.segment_length`: at least 8 segments), mode shapes."""
    out = Path(directory)
    names = [str(c) for c in record.outputs]
    fac = ident.factorization
    top = min(max(2 * ident.order, 20), fac.numerical_rank)
    rows = stabilization_rows(fac, ident.dt, range(2, top + 1, 2))
    measured = h1_frf(record.u, record.y, record.dt,
                      nperseg=min(nperseg or segment_length(record.samples), record.samples))
    model = model_frf(ident.A, ident.B, ident.C, ident.D, ident.dt, measured.frequency_hz)
    return [
        hankel_singular_values(ident.hankel_singular_values, ident.order,
                               out / "hankel_singular_values.png"),
        stabilization_diagram([r.order for r in rows], [r.modes.frequency_hz for r in rows],
                              [r.stable for r in rows], ident.order,
                              out / "stabilization.png", nyquist_hz=0.5 / ident.dt,
                              frequency_ci_hz=(None if ident.refinement is None
                                               else ident.refinement.frequency_ci_hz)),
        frf(measured.frequency_hz, measured.H, measured.coherence, model,
            [str(c) for c in record.inputs], names, out / "frf.png",
            input_units=[c.unit for c in record.inputs],
            output_units=[c.unit for c in record.outputs], segments=measured.segments),
        mode_shapes(ident.modes.frequency_hz, ident.modes.damping_ratio, ident.modes.shapes,
                    names, out / "mode_shapes.png"),
    ]


def mac_matrix(frequency_hz: np.ndarray, values: np.ndarray, path: Path,
               title: str = "AutoMAC of the identified modes") -> Path:
    """The MAC between every pair of modes as a grid (1 on the diagonal)."""
    labels = [f"{f:.3g} Hz" for f in frequency_hz]
    fig, ax = plt.subplots(figsize=(1.1 * len(labels) + 3, 1.0 * len(labels) + 2.5))
    image = ax.imshow(values, vmin=0, vmax=1, cmap="viridis")
    for i in range(len(labels)):
        for j in range(len(labels)):
            ax.text(j, i, f"{values[i, j]:.2f}", ha="center", va="center", color="w", fontsize=8)
    ax.set_xticks(range(len(labels)), labels, rotation=45, fontsize=8)
    ax.set_yticks(range(len(labels)), labels, fontsize=8)
    ax.set_xlabel("mode [Hz]")
    ax.set_ylabel("mode [Hz]")
    ax.set_title(title, fontsize=9)
    fig.colorbar(image, ax=ax, label="MAC [-]")
    fig.tight_layout()
    return _save(fig, path)


def output_only_plots(ident: OutputOnlyIdentification, record: Record, directory: str | Path
                      ) -> list[Path]:
    """SSI-COV's figures: singular values of the covariances' Toeplitz matrix, stabilization
    diagram with the 95 % intervals, mode shapes and the AutoMAC."""
    out = Path(directory)
    names = [str(c) for c in record.outputs]
    fac = ident.factorization
    top = min(max(2 * ident.order, 20), fac.numerical_rank)
    rows = stabilization_rows(fac, ident.dt, range(2, top + 1, 2))
    return [
        hankel_singular_values(ident.singular_values, ident.order,
                               out / "singular_values.png",
                               title="Singular values of the output covariances (SSI-COV)"),
        stabilization_diagram([r.order for r in rows], [r.modes.frequency_hz for r in rows],
                              [r.stable for r in rows], ident.order, out / "stabilization.png",
                              nyquist_hz=0.5 / ident.dt, frequency_ci_hz=ident.frequency_ci_hz),
        mode_shapes(ident.modes.frequency_hz, ident.modes.damping_ratio, ident.modes.shapes,
                    names, out / "mode_shapes.png"),
        mac_matrix(ident.modes.frequency_hz, ident.auto_mac, out / "mac.png"),
    ]


def mode_comparison(models: dict[str, list[dict[str, float]]], path: Path) -> Path:
    """Frequency against damping ratio of each model's modes; marker size ~ peak contribution."""
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for c, (label, modes) in enumerate(models.items()):
        peaks = np.array([m["peak"] for m in modes])
        sizes = 20 + 200 * peaks / peaks.max() if peaks.size else []
        ax.scatter([m["frequency_hz"] for m in modes], [m["damping_ratio"] for m in modes],
                   s=sizes, facecolors="none", edgecolors=f"C{c}", label=label)
    ax.set_yscale("log")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("damping ratio [-]")
    ax.set_title("Identified modes (marker size: resonance peak)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)
