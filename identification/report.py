"""The identification result as a JSON-ready document and as a terminal table."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from identification.modal import ModalTable
from identification.pipeline import Identification
from stillframe.commands.common import format_table


def modes_document(modes: ModalTable, consistent: Sequence[bool]) -> list[dict[str, Any]]:
    """Modes sorted by frequency: frequency, damping ratio, shape as [magnitude, phase] and
    whether the mode persists at higher orders (:mod:`identification.quality`)."""
    return [{"frequency_hz": float(modes.frequency_hz[k]),
             "damping_ratio": float(modes.damping_ratio[k]),
             "shape": modes.magnitude_phase(k),
             "consistent": bool(consistent[k])} for k in range(len(modes))]


def identification_document(ident: Identification, order_auto: bool) -> dict[str, Any]:
    """``{"order", "dt", "modes", "hankel_singular_values", "method", ...}``."""
    doc: dict[str, Any] = {
        "order": ident.order,
        "dt": ident.dt,
        "method": ident.method,
        "modes": modes_document(ident.modes, ident.consistent),
        "hankel_singular_values": [float(s) for s in ident.hankel_singular_values],
        "observer_order": ident.observer_order,
        "order_gap": ident.order_gap if np.isfinite(ident.order_gap) else None,
        "warnings": list(ident.warnings),
    }
    if order_auto:
        doc["order_selection"] = {"criterion": "largest sigma_n / sigma_n+1",
                                  "gap": ident.order_gap}
    return doc


def modes_table(modes: ModalTable, consistent: Sequence[bool], output_names: list[str]) -> str:
    """One row per mode: frequency, damping ratio, consistency, shape magnitude/phase per
    output."""
    headers = ["mode", "f [Hz]", "zeta", "consistent",
               *(f"{n} |.|/∠[deg]" for n in output_names)]
    rows = []
    for k in range(len(modes)):
        shape = [f"{mag:.3f}/{np.degrees(phase):+.1f}"
                 for mag, phase in modes.magnitude_phase(k)]
        rows.append([k + 1, float(modes.frequency_hz[k]), float(modes.damping_ratio[k]),
                     "yes" if consistent[k] else "NO", *shape])
    return format_table(headers, rows)


def format_matrix(rows: list[list[float]]) -> str:
    """A matrix as aligned rows, 6 significant digits."""
    return "\n".join("  ".join(f"{v:12.6g}" for v in row) for row in rows)
