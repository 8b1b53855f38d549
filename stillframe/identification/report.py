"""The identification result as a JSON-ready document and as a terminal table."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from stillframe.identification.modal import ModalTable
from stillframe.identification.pem import Refinement
from stillframe.identification.pipeline import Identification
from stillframe.identification.ssi_cov import OutputOnlyIdentification
from stillframe.text_table import format_table

WithIntervals = Refinement | OutputOnlyIdentification
"""What carries the modes' 95 % intervals (``frequency_ci_hz``, ``damping_ci``)."""


def modes_document(modes: ModalTable, consistent: Sequence[bool],
                   refinement: WithIntervals | None = None) -> list[dict[str, Any]]:
    """Modes sorted by frequency: frequency, damping ratio, shape as [magnitude, phase],
    whether the mode persists at higher orders (:mod:`stillframe.identification.quality`) and, with
    the refinement, the 95 % intervals ``frequency_ci_hz`` and ``damping_ci``."""
    docs = [{"frequency_hz": float(modes.frequency_hz[k]),
             "damping_ratio": float(modes.damping_ratio[k]),
             "shape": modes.magnitude_phase(k),
             "consistent": bool(consistent[k])} for k in range(len(modes))]
    if refinement is not None:
        for k, doc in enumerate(docs):
            doc["frequency_ci_hz"] = refinement.frequency_ci_hz[k].tolist()
            doc["damping_ci"] = refinement.damping_ci[k].tolist()
    return docs


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
    return _document(ident, ident.refinement, order_auto, {
        "hankel_singular_values": [float(s) for s in ident.hankel_singular_values],
        "observer_order": ident.observer_order})


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
    consistency, shape magnitude/phase per output."""
    intervals = ["f 95 % CI [Hz]", "zeta 95 % CI"] if refinement is not None else []
    headers = ["mode", "f [Hz]", "zeta", *intervals, "consistent",
               *(f"{n} |.|/∠[deg]" for n in output_names)]
    rows = []
    for k in range(len(modes)):
        shape = [f"{mag:.3f}/{np.degrees(phase):+.1f}"
                 for mag, phase in modes.magnitude_phase(k)]
        ci = [] if refinement is None else [
            "{:.5g} .. {:.5g}".format(*refinement.frequency_ci_hz[k]),
            "{:.4g} .. {:.4g}".format(*refinement.damping_ci[k])]
        rows.append([k + 1, float(modes.frequency_hz[k]), float(modes.damping_ratio[k]), *ci,
                     "yes" if consistent[k] else "NO", *shape])
    return format_table(headers, rows)


def format_matrix(rows: list[list[float]]) -> str:
    """A matrix as aligned rows, 6 significant digits."""
    return "\n".join("  ".join(f"{v:12.6g}" for v in row) for row in rows)
