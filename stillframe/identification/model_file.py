"""The identified-model file: what `stillframe identify --save-model` writes and the estimator and
controller nodes load (thesis's identify-then-design loop, §5.5–5.6).

Format (version 1): a NumPy ``.npz`` archive, read with ``numpy.load(path, allow_pickle=False)``.

Arrays (float64 unless noted; n states, r inputs, m outputs, k modes, d DOFs):

=====================  ==========  ===========================================================
key                    shape       meaning
=====================  ==========  ===========================================================
``A B C D``            n×n … m×r   discrete model ``x(k+1) = A x + B u``, ``y = C x + D u``
``G`` (optional)       n×m         observer gain, ``xhat(k+1) = (A + G C) xhat + (B + G D) u - G y``
``mode_frequency_hz``  k           natural frequencies, ascending
``mode_damping_ratio`` k           damping ratios
``mode_eigenvalue``    k complex   continuous eigenvalues ``ln(lambda) / dt``
``mode_shape``         m×k complex shapes at the outputs, reference component 1 (magnitude
                                   ``abs``, phase ``angle`` in rad)
``M K R`` (optional)   d×d         MKR mass, stiffness and damping matrices (all three or none)
``meta``               0-d str     JSON, below
=====================  ==========  ===========================================================

``meta``: ``{"format": "stillframe-identified-model", "version": 1, "dt": seconds,
"inputs": [r channel names], "outputs": [m channel names], "provenance": {...}}``; provenance
holds at least ``method`` and ``order`` and, from a bag, ``bag`` and the topics; MKR results may
add ``rayleigh_alpha``/``rayleigh_beta`` and ``mkr`` (sensor/actuator DOFs, output type).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import InputError
from stillframe.identification.mkr import PhysicalModel
from stillframe.identification.modal import ModalTable
from stillframe.identification.pipeline import Identification

Array = NDArray[np.float64]
FORMAT = "stillframe-identified-model"
VERSION = 1
MODAL_KEYS = ("mode_frequency_hz", "mode_damping_ratio", "mode_eigenvalue", "mode_shape")
ALLOWED_KEYS = {"A", "B", "C", "D", "G", "M", "K", "R", "meta", *MODAL_KEYS}


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
    _validate(model, str(path))
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
    meta = {"format": FORMAT, "version": VERSION, "dt": model.dt, "inputs": model.inputs,
            "outputs": model.outputs, "provenance": model.provenance, **model.extra}
    try:
        arrays["meta"] = np.array(json.dumps(meta))
    except TypeError as exc:
        raise InputError(f"{path}: model metadata is not JSON-serialisable: {exc}") from None
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)


def load_model(path: str | Path) -> IdentifiedModel:
    """Read and validate a model file; any defect raises :class:`InputError` naming it."""
    name = str(path)
    try:
        archive = np.load(path, allow_pickle=False)
        if not isinstance(archive, np.lib.npyio.NpzFile):
            raise InputError(f"{name}: not a .npz model file (a single array)")
        with archive:
            data = {key: archive[key] for key in archive.files}
    except FileNotFoundError:
        raise InputError(f"{name}: model file not found") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(f"{name}: not a readable .npz model file ({exc})") from None
    unknown = set(data) - ALLOWED_KEYS
    if unknown:
        raise InputError(f"{name}: unknown arrays {sorted(unknown)}")
    missing = {"A", "B", "C", "D", "meta", *MODAL_KEYS} - set(data)
    if missing:
        raise InputError(f"{name}: missing arrays {sorted(missing)}")
    try:
        meta = json.loads(str(data["meta"]))
    except json.JSONDecodeError as exc:
        raise InputError(f"{name}: 'meta' is not valid JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise InputError(f"{name}: 'meta.format' is not {FORMAT!r}")
    if meta.get("version") != VERSION:
        raise InputError(f"{name}: unsupported model file version {meta.get('version')!r}")
    physical_keys = {"M", "K", "R"} & set(data)
    if physical_keys and physical_keys != {"M", "K", "R"}:
        raise InputError(f"{name}: M, K and R must be given together, "
                         f"found {sorted(physical_keys)}")
    dt = meta.get("dt")
    model = IdentifiedModel(
        A=data["A"], B=data["B"], C=data["C"], D=data["D"],
        dt=dt if isinstance(dt, int | float) and not isinstance(dt, bool) else float("nan"),
        modes=ModalTable(frequency_hz=data["mode_frequency_hz"],
                         damping_ratio=data["mode_damping_ratio"],
                         eigenvalues=data["mode_eigenvalue"], shapes=data["mode_shape"]),
        inputs=meta.get("inputs"), outputs=meta.get("outputs"),
        provenance=meta.get("provenance"), G=data.get("G"),
        physical=PhysicalModel(M=data["M"], K=data["K"], R=data["R"]) if physical_keys else None,
        extra={k: v for k, v in meta.items()
               if k not in ("format", "version", "dt", "inputs", "outputs", "provenance")},
    )
    _validate(model, name)
    return model


def _matrix(name: str, key: str, value: Any, shape: tuple[int, ...], kind: str = "f") -> None:
    arr = np.asarray(value)
    if arr.dtype.kind not in ("f", "i") + (("c",) if kind == "c" else ()):
        raise InputError(f"{name}: '{key}' must be numeric, got dtype {arr.dtype}")
    if arr.shape != shape:
        raise InputError(f"{name}: '{key}' has shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: '{key}' contains NaN or inf")


def _validate(model: IdentifiedModel, name: str) -> None:
    A = np.asarray(model.A)
    if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] == 0:
        raise InputError(f"{name}: 'A' must be a non-empty square matrix, got shape {A.shape}")
    n = A.shape[0]
    B, C = np.asarray(model.B), np.asarray(model.C)
    if B.ndim != 2 or C.ndim != 2:
        raise InputError(f"{name}: 'B' and 'C' must be matrices")
    r, m = B.shape[1], C.shape[0]
    for key, value, shape in (("A", A, (n, n)), ("B", B, (n, r)), ("C", C, (m, n)),
                              ("D", model.D, (m, r))):
        _matrix(name, key, value, shape)
    if model.G is not None:
        _matrix(name, "G", model.G, (n, m))
    if not (isinstance(model.dt, int | float) and np.isfinite(model.dt) and model.dt > 0):
        raise InputError(f"{name}: 'meta.dt' must be a positive number of seconds")
    for key, labels, count in (("inputs", model.inputs, r), ("outputs", model.outputs, m)):
        if not (isinstance(labels, list) and all(isinstance(s, str) for s in labels)
                and len(labels) == count):
            raise InputError(f"{name}: 'meta.{key}' must list {count} channel names")
    if not isinstance(model.provenance, dict) or not {"method", "order"} <= set(model.provenance):
        raise InputError(f"{name}: 'meta.provenance' must be an object with 'method' and 'order'")
    k = np.asarray(model.modes.frequency_hz).size
    _matrix(name, "mode_frequency_hz", model.modes.frequency_hz, (k,))
    _matrix(name, "mode_damping_ratio", model.modes.damping_ratio, (k,))
    _matrix(name, "mode_eigenvalue", model.modes.eigenvalues, (k,), kind="c")
    _matrix(name, "mode_shape", model.modes.shapes, (m, k), kind="c")
    if np.any(np.diff(model.modes.frequency_hz) < 0):
        raise InputError(f"{name}: 'mode_frequency_hz' must be in ascending order")
    if model.physical is not None:
        d = np.asarray(model.physical.M).shape[0] if np.asarray(model.physical.M).ndim else 0
        for key in ("M", "K", "R"):
            _matrix(name, key, getattr(model.physical, key), (d, d))


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
