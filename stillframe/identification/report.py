"""The identification result as a JSON-ready document and as a terminal table."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from stillframe.identification.modal import ModalTable
from stillframe.identification.pem import Z95, Refinement
from stillframe.identification.pipeline import Identification
from stillframe.identification.ssi_cov import OutputOnlyIdentification
from stillframe.text_table import format_table

WithIntervals = Refinement | OutputOnlyIdentification
"""What carries the modes' 95 % intervals (``frequency_ci_hz``, ``damping_ci``)."""


def modes_document(modes: ModalTable, consistent: Sequence[bool],
                   refinement: WithIntervals | None = None,
                   reference: int | None = None) -> list[dict[str, Any]]:
    """Modes sorted by frequency: frequency, damping ratio, shape as [magnitude, phase],
    whether the mode persists at higher orders (:mod:`stillframe.identification.quality`) and, with
    intervals, ``frequency_ci_hz`` and ``damping_ci`` (None where there is none), and with the
    refinement each shape component's 95 % phase interval ``shape_phase_ci`` [rad]."""
    docs = [{"frequency_hz": float(modes.frequency_hz[k]),
             "damping_ratio": float(modes.damping_ratio[k]),
             "shape": modes.magnitude_phase(k),
             "consistent": bool(consistent[k])} for k in range(len(modes))]
    if refinement is not None:
        phase = (refinement.phase_std(reference) if isinstance(refinement, Refinement)
                 else None)
        for k, doc in enumerate(docs):
            doc["frequency_ci_hz"] = interval(refinement.frequency_ci_hz[k])
            doc["damping_ci"] = interval(refinement.damping_ci[k])
            if phase is not None:
                doc["shape_phase_ci"] = [
                    interval(np.array([ph - Z95 * sd, ph + Z95 * sd]))
                    for (_, ph), sd in zip(modes.magnitude_phase(k), phase[:, k], strict=True)]
    return docs


def interval(pair: np.ndarray) -> list[float] | None:
    """``[low, high]``, or None where there is no interval (NaN: the reason is in the
    warnings)."""
    return pair.tolist() if np.all(np.isfinite(pair)) else None


def refinement_document(refinement: Refinement) -> dict[str, Any]:
    """How the refinement's search ended and what its intervals rest on."""
    return {"noise_model": refinement.noise_model,
            "converged": refinement.converged, "stop": refinement.stop,
            "iterations": refinement.iterations, "evaluations": refinement.evaluations,
            "covariance": f"sandwich with a Newey-West score covariance over "
                          f"{refinement.hac_lags} lags",
            "identifiable_parameters": refinement.parameter_count}


def _document(ident: Identification | OutputOnlyIdentification, intervals: WithIntervals | None,
              order_auto: bool, extra: dict[str, Any]) -> dict[str, Any]:
    doc: dict[str, Any] = {
        "order": ident.order, "dt": ident.dt, "method": ident.method,
        "modes": modes_document(ident.modes, ident.consistent, intervals), **extra,
        "order_gap": ident.order_gap if np.isfinite(ident.order_gap) else None,
        "warnings": list(ident.warnings),
    }
    if order_auto:
        doc["order_selection"] = {"criterion": "largest sigma_n / sigma_n+1",
                                  "gap": ident.order_gap}
    return doc


def identification_document(ident: Identification, order_auto: bool) -> dict[str, Any]:
    """``{"order", "dt", "modes", "hankel_singular_values", "method", ...}``."""
    extra = {"hankel_singular_values": [float(s) for s in ident.hankel_singular_values],
             "observer_order": ident.observer_order}
    if ident.refinement is not None:
        extra["refinement"] = refinement_document(ident.refinement)
    return _document(ident, ident.refinement, order_auto, extra)


def output_only_document(ident: OutputOnlyIdentification, order_auto: bool) -> dict[str, Any]:
    """The SSI-COV result: ``{"order", "dt", "method", "modes" (with intervals), "auto_mac",
    "singular_values", "block_rows", "order_gap", "warnings"}``."""
    return _document(ident, ident, order_auto, {
        "auto_mac": ident.auto_mac.tolist(),
        "singular_values": [float(s) for s in ident.singular_values],
        "block_rows": ident.block_rows})


def modes_table(modes: ModalTable, consistent: Sequence[bool], output_names: list[str],
                refinement: WithIntervals | None = None) -> str:
    """One row per mode: frequency, damping ratio (with the refinement: their 95 % intervals),
    consistency, shape magnitude/phase per output (with the refinement: ± the phase's 95 %
    half-width in degrees)."""
    intervals = ["f 95 % CI [Hz]", "zeta 95 % CI"] if refinement is not None else []
    phase = refinement.phase_std() if isinstance(refinement, Refinement) else None
    headers = ["mode", "f [Hz]", "zeta", *intervals, "consistent",
               *(f"{n} |.|/∠[deg]" for n in output_names)]
    rows = []
    for k in range(len(modes)):
        shape = [f"{mag:.3f}/{np.degrees(phase):+.1f}"
                 for mag, phase in modes.magnitude_phase(k)]
        ci = [] if refinement is None else [
            _interval_text(refinement.frequency_ci_hz[k], 5),
            _interval_text(refinement.damping_ci[k], 4)]
        if phase is not None:
            shape = [f"{text}±{np.degrees(Z95 * sd):.0f}" if np.isfinite(sd) and sd > 0
                     else text for text, sd in zip(shape, phase[:, k], strict=True)]
        rows.append([k + 1, float(modes.frequency_hz[k]), float(modes.damping_ratio[k]), *ci,
                     "yes" if consistent[k] else "NO", *shape])
    return format_table(headers, rows)


def _interval_text(pair: np.ndarray, digits: int) -> str:
    if not np.all(np.isfinite(pair)):
        return "none (see warnings)"
    return f"{pair[0]:.{digits}g} .. {pair[1]:.{digits}g}"


def refinement_text(refinement: Refinement) -> str:
    """One line: the model kept, how the search ended and what the intervals rest on."""
    ended = ("converged" if refinement.converged else "NOT converged") + f" ({refinement.stop})"
    intervals = (f"95 % intervals from a sandwich covariance (Newey-West, {refinement.hac_lags} "
                 "lags)" if np.isfinite(refinement.frequency_ci_hz).any()
                 else "no 95 % intervals (see warnings)")
    return (f"refinement: {refinement.noise_model} model, {ended} after "
            f"{refinement.iterations} iterations; {intervals}")


def format_matrix(rows: list[list[float]]) -> str:
    """A matrix as aligned rows, 6 significant digits."""
    return "\n".join("  ".join(f"{v:12.6g}" for v in row) for row in rows)
