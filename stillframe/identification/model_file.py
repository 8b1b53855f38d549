"""The identified-model file of an identification (format: :mod:`stillframe.contract.model_file`):
what ``stillframe identify --save-model`` writes and ``stillframe identify`` reads back."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stillframe.contract.model_file import META_KEYS, read_archive, write_archive
from stillframe.identification.mkr import PhysicalModel
from stillframe.identification.modal import ModalTable
from stillframe.identification.pipeline import Identification

Array = NDArray[np.float64]


@dataclass(frozen=True)
class IdentifiedModel:
    """Everything the model file holds."""

    A: Array
    B: Array
    C: Array
    D: Array
    dt: float
    modes: ModalTable
    inputs: list[str]
    outputs: list[str]
    provenance: dict[str, Any]
    G: Array | None = None
    physical: PhysicalModel | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    """Any further JSON-serialisable metadata (kept under ``meta``)."""


def save_model(path: str | Path, model: IdentifiedModel) -> None:
    """Write ``model`` to ``path`` (``.npz``) after validating it."""
    arrays: dict[str, Any] = {
        "A": model.A, "B": model.B, "C": model.C, "D": model.D,
        "mode_frequency_hz": model.modes.frequency_hz,
        "mode_damping_ratio": model.modes.damping_ratio,
        "mode_eigenvalue": model.modes.eigenvalues,
        "mode_shape": model.modes.shapes,
    }
    if model.G is not None:
        arrays["G"] = model.G
    if model.physical is not None:
        arrays.update(M=model.physical.M, K=model.physical.K, R=model.physical.R)
    write_archive(path, arrays, {"dt": model.dt, "inputs": model.inputs,
                                 "outputs": model.outputs, "provenance": model.provenance,
                                 **model.extra})


def load_model(path: str | Path) -> IdentifiedModel:
    """Read and validate a model file; any defect raises an InputError naming it."""
    archive = read_archive(path)
    data, meta = archive.arrays, archive.meta
    return IdentifiedModel(
        A=data["A"], B=data["B"], C=data["C"], D=data["D"], dt=float(meta["dt"]),
        modes=ModalTable(frequency_hz=data["mode_frequency_hz"],
                         damping_ratio=data["mode_damping_ratio"],
                         eigenvalues=data["mode_eigenvalue"], shapes=data["mode_shape"]),
        inputs=meta["inputs"], outputs=meta["outputs"], provenance=meta["provenance"],
        G=data.get("G"),
        physical=PhysicalModel(M=data["M"], K=data["K"], R=data["R"]) if archive.has_mkr
        else None,
        extra={k: v for k, v in meta.items() if k not in META_KEYS},
    )


def model_from_identification(ident: Identification, inputs: list[str], outputs: list[str],
                              provenance: dict[str, Any] | None = None,
                              physical: PhysicalModel | None = None,
                              extra: dict[str, Any] | None = None) -> IdentifiedModel:
    """The file content for an :class:`Identification`; method, order, observer order and the
    order gap are added to ``provenance`` (which should name the bag and topics)."""
    prov = {"method": ident.method, "order": ident.order, "observer_order": ident.observer_order,
            "order_gap": ident.order_gap if np.isfinite(ident.order_gap) else None,
            **(provenance or {})}
    return IdentifiedModel(A=ident.A, B=ident.B, C=ident.C, D=ident.D, dt=ident.dt,
                           modes=ident.modes, inputs=list(inputs), outputs=list(outputs),
                           provenance=prov, G=ident.G, physical=physical, extra=dict(extra or {}))
