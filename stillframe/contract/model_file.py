"""The identified-model file format: what ``stillframe identify --save-model`` writes and the
estimator, controller and simulator load (the thesis's identify-then-design loop, §5.5–5.6).

This module is the one reader, writer and validator of the format;
:mod:`stillframe.identification.model_file` maps an identification onto it and
:mod:`stillframe.design.identified` builds a model from its MKR matrices.

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
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import scipy.linalg

from stillframe.config.scene import DAMPING_COEFFICIENT, FLOOR_MASS, FREQUENCY_HZ
from stillframe.config.schema import Check, show
from stillframe.errors import InputError
from stillframe.files import open_input, open_output, size_text

__all__ = ["META_KEYS", "STRUCTURE", "ModelArchive", "Physical", "check_structure", "read_archive",
           "validate", "write_archive"]

FORMAT = "stillframe-identified-model"
VERSION = 1
MODAL_KEYS = ("mode_frequency_hz", "mode_damping_ratio", "mode_eigenvalue", "mode_shape")
MKR_KEYS = ("M", "K", "R")
ALLOWED_KEYS = {"A", "B", "C", "D", "G", "meta", *MKR_KEYS, *MODAL_KEYS}
#: ``meta`` keys with a meaning of their own; any other key is kept as extra metadata
META_KEYS = ("format", "version", "dt", "inputs", "outputs", "provenance")
#: a model file's size at most, on disk and unpacked (a model of 200 states takes under 1 MiB)
MAX_MODEL_BYTES = 16 << 20
#: relative tolerance of symmetry and of a semidefinite matrix's least eigenvalue
SYMMETRY_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Physical:
    """A matrix of an identified structure: what it is, the check of its diagonal (the scene
    key's own, config/scene.py) and the definiteness physics asks of it (symmetric always)."""

    doc: str
    diagonal: Check | None
    definite: Literal["positive definite", "positive semidefinite"]


#: the matrices of an identified structure, by their keys in a ``.npz`` model file (``mass``,
#: ``stiffness`` and ``damping`` in a YAML one); the natural frequencies of M and K must lie
#: where the scene's frequencies may (:data:`~stillframe.config.scene.FREQUENCY_HZ`), which
#: bounds a huge stiffness
STRUCTURE = {
    "M": Physical("mass [kg]", FLOOR_MASS, "positive definite"),
    "K": Physical("stiffness [N/m]", None, "positive semidefinite"),
    "R": Physical("damping [N s/m]", DAMPING_COEFFICIENT, "positive semidefinite"),
}


def check_structure(matrices: dict[str, np.ndarray], name: str,
                    labels: dict[str, str] | None = None) -> None:
    """InputError naming the file and the entry unless the structure's M, K, R (``labels``: the
    file's own names for them) are finite square matrices of one size, symmetric, as definite
    as :data:`STRUCTURE` says, with diagonals within their checks and natural frequencies
    within :data:`~stillframe.config.scene.FREQUENCY_HZ`."""
    labels = labels or {key: key for key in STRUCTURE}
    size = np.asarray(matrices["M"]).shape[:1] * 2
    for key, physical in STRUCTURE.items():
        where = f"{name}: {labels[key]!r} ({physical.doc})"
        matrix = np.asarray(matrices[key])
        _matrix(name, labels[key], matrix, size)
        scale = float(np.max(np.abs(matrix), initial=0.0))
        if np.max(np.abs(matrix - matrix.T), initial=0.0) > SYMMETRY_TOLERANCE * scale:
            raise InputError(f"{where}: not symmetric")
        diagonal = tuple(float(v) for v in np.diag(matrix))
        problem = physical.diagonal(diagonal) if physical.diagonal else None
        if problem:
            raise InputError(f"{where}: its diagonal {problem} (got {show(diagonal)})")
        least = float(np.min(np.linalg.eigvalsh(matrix)))
        floor = 0.0 if physical.definite == "positive definite" else -SYMMETRY_TOLERANCE * scale
        if least < floor or (physical.definite == "positive definite" and least <= 0.0):
            raise InputError(f"{where}: not {physical.definite} (least eigenvalue {least:.6g})")
    squares = scipy.linalg.eigh(matrices["K"], matrices["M"], eigvals_only=True)
    hz = tuple(float(np.sqrt(max(w, 0.0)) / (2 * np.pi)) for w in squares)
    problem = FREQUENCY_HZ(hz)
    if problem:
        raise InputError(f"{name}: {labels['K']!r} ({STRUCTURE['K'].doc}) with "
                         f"{labels['M']!r}: natural frequencies {problem} Hz (got {show(hz)})")


@dataclass(frozen=True)
class ModelArchive:
    """The arrays of a model file and its decoded ``meta`` (validated)."""

    arrays: dict[str, np.ndarray]
    meta: dict[str, Any]

    @property
    def has_mkr(self) -> bool:
        """Whether the archive holds the identified M, K, R (all of :data:`MKR_KEYS`)."""
        return set(MKR_KEYS) <= set(self.arrays)


def write_archive(path: str | Path, arrays: dict[str, Any], meta: dict[str, Any]) -> None:
    """Validate and write a model file (``meta`` gets the format and version)."""
    meta = {"format": FORMAT, "version": VERSION, **meta}
    validate(arrays, meta, str(path))
    try:
        encoded = np.array(json.dumps(meta))
    except TypeError as exc:
        raise InputError(f"{path}: model metadata is not JSON-serialisable: {exc}") from None
    with open_output(path, what="model file") as handle:
        np.savez(handle, **arrays, meta=encoded)


def _check_members(archive: np.lib.npyio.NpzFile, name: str) -> None:
    """Before any array is read: the archive unpacks to at most :data:`MAX_MODEL_BYTES`, and no
    array's header claims more data than its member holds (numpy allocates what the header
    claims before it reads)."""
    members = archive.zip.infolist()
    unpacked = sum(info.file_size for info in members)
    if unpacked > MAX_MODEL_BYTES:
        raise InputError(f"{name}: unpacks to {size_text(unpacked)}, more than the "
                         f"{size_text(MAX_MODEL_BYTES)} a model file may have")
    for info in members:
        with archive.zip.open(info) as member:
            version = np.lib.format.read_magic(member)
            header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                      else np.lib.format.read_array_header_2_0)
            shape, _, dtype = header(member)
            if math.prod(shape) * dtype.itemsize > info.file_size:
                raise InputError(f"{name}: '{info.filename.removesuffix('.npy')}' claims "
                                 f"shape {shape} of {dtype}, more than its "
                                 f"{size_text(info.file_size)} hold")


def read_archive(path: str | Path) -> ModelArchive:
    """Read and validate a model file; any defect raises :class:`InputError` naming it."""
    name = str(path)
    with open_input(path, what="model file", max_bytes=MAX_MODEL_BYTES) as stream:
        try:
            archive = np.load(stream, allow_pickle=False)
            if not isinstance(archive, np.lib.npyio.NpzFile):
                raise InputError(f"{name}: not a .npz model file (a single array)")
            with archive:
                _check_members(archive, name)
                data = {key: archive[key] for key in archive.files}
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
            raise InputError(f"{name}: not a readable .npz model file ({exc})") from None
    unknown = set(data) - ALLOWED_KEYS
    if unknown:
        raise InputError(f"{name}: unknown arrays {sorted(unknown)}")
    missing = {"A", "B", "C", "D", "meta", *MODAL_KEYS} - set(data)
    if missing:
        raise InputError(f"{name}: missing arrays {sorted(missing)}")
    try:
        meta = json.loads(str(data.pop("meta")))
    except json.JSONDecodeError as exc:
        raise InputError(f"{name}: 'meta' is not valid JSON ({exc})") from None
    validate(data, meta, name)
    return ModelArchive(data, meta)


def _matrix(name: str, key: str, value: Any, shape: tuple[int, ...], kind: str = "f") -> None:
    arr = np.asarray(value)
    if arr.dtype.kind not in ("f", "i") + (("c",) if kind == "c" else ()):
        raise InputError(f"{name}: '{key}' must be numeric, got dtype {arr.dtype}")
    if arr.shape != shape:
        raise InputError(f"{name}: '{key}' has shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: '{key}' contains NaN or inf")


def validate(arrays: dict[str, Any], meta: Any, name: str) -> None:
    """The format's rules: ``meta`` names format and version; A, B, C, D (and G) agree in size;
    dt > 0; one channel name per input and output; provenance with method and order; the modal
    table consistent and ascending; M, K, R square, of one size, and given together."""
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise InputError(f"{name}: 'meta.format' is not {FORMAT!r}")
    if meta.get("version") != VERSION:
        raise InputError(f"{name}: unsupported model file version {meta.get('version')!r}")
    A = np.asarray(arrays["A"])
    if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] == 0:
        raise InputError(f"{name}: 'A' must be a non-empty square matrix, got shape {A.shape}")
    n = A.shape[0]
    B, C = np.asarray(arrays["B"]), np.asarray(arrays["C"])
    if B.ndim != 2 or C.ndim != 2:
        raise InputError(f"{name}: 'B' and 'C' must be matrices")
    r, m = B.shape[1], C.shape[0]
    for key, shape in (("A", (n, n)), ("B", (n, r)), ("C", (m, n)), ("D", (m, r))):
        _matrix(name, key, arrays[key], shape)
    if arrays.get("G") is not None:
        _matrix(name, "G", arrays["G"], (n, m))
    dt = meta.get("dt")
    if not (isinstance(dt, int | float) and not isinstance(dt, bool) and np.isfinite(dt)
            and dt > 0):
        raise InputError(f"{name}: 'meta.dt' must be a positive number of seconds")
    for key, count in (("inputs", r), ("outputs", m)):
        labels = meta.get(key)
        if not (isinstance(labels, list) and all(isinstance(s, str) for s in labels)
                and len(labels) == count):
            raise InputError(f"{name}: 'meta.{key}' must list {count} channel names")
    provenance = meta.get("provenance")
    if not isinstance(provenance, dict) or not {"method", "order"} <= set(provenance):
        raise InputError(f"{name}: 'meta.provenance' must be an object with 'method' and 'order'")
    k = np.asarray(arrays["mode_frequency_hz"]).size
    _matrix(name, "mode_frequency_hz", arrays["mode_frequency_hz"], (k,))
    _matrix(name, "mode_damping_ratio", arrays["mode_damping_ratio"], (k,))
    _matrix(name, "mode_eigenvalue", arrays["mode_eigenvalue"], (k,), kind="c")
    _matrix(name, "mode_shape", arrays["mode_shape"], (m, k), kind="c")
    if np.any(np.diff(arrays["mode_frequency_hz"]) < 0):
        raise InputError(f"{name}: 'mode_frequency_hz' must be in ascending order")
    present = [key for key in MKR_KEYS if arrays.get(key) is not None]
    if present and len(present) != len(MKR_KEYS):
        raise InputError(f"{name}: M, K and R must be given together, found {sorted(present)}")
    if present:
        M = np.asarray(arrays["M"])
        d = M.shape[0] if M.ndim else 0
        for key in MKR_KEYS:
            _matrix(name, key, arrays[key], (d, d))
