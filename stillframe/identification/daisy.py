"""Identification of real measured data: the DaISy steel subframe (96-013), OKID + ERA and
OKID + ERA/DC beside N4SID (``nfoursid``) on the same split.

The record (8523 samples at 1024 Hz, 2 shaker forces, 28 accelerations; BSD-3, SLICOT) is
linearly detrended, as in the toolbox's demo, and split in halves: the models are identified on
the first half and validated on the second, which they never see (simulated from the measured
input, :mod:`stillframe.identification.validation`). Choices, fixed before looking at the held-out
half:

- order 20 and N4SID block rows 21, the toolbox demo's values;
- the 4 outputs with the highest mean multiple coherence with the two inputs on the
  identification half (H1 estimate). With more outputs the system Markov parameters that OKID
  recovers (eq. 3.107) grow without bound on this record, so OKID cannot be run on all 28 of
  them; N4SID gets the same 4 for a like-for-like comparison;
- OKID's observer order p: the value in ``ceil(n / m) .. 12`` whose model fits best when
  identified on the first three quarters of the identification half and simulated on its last
  quarter.

``okid-era-oe``: the OKID + ERA model (its p as above) refined on the identification half as an
output-error model (:func:`stillframe.identification.pem.refine_prediction_error` with
``innovations=False``:
least squares on the simulation error from the input alone, which is what the held-out fit
measures).

Dominant modes are those with the largest peak of their modal contribution
``|| C psi_i w_i B || / (1 - |lambda_i|)`` (the height of the mode's resonance peak in the
FRF), among modes with damping ratio below 0.2.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.io
from scipy import signal

from stillframe.config.environment import value
from stillframe.errors import IdentificationError, InputError
from stillframe.files import open_input
from stillframe.identification.frf import h1_frf
from stillframe.identification.modal import modal_parameters
from stillframe.identification.n4sid import identify_n4sid
from stillframe.identification.pem import refine_prediction_error
from stillframe.identification.pipeline import identify
from stillframe.identification.validation import fit_percent, simulate_fitted
from stillframe.locations import DATASETS_DIR

#: the record's file under a datasets folder
RECORD = Path("daisy") / "flexible_structure_dat.mat"


def default_path() -> Path:
    """The record in ``STILLFRAME_DATASETS``, else in ``datasets/`` of the checkout (which
    ships it with its licence)."""
    return Path(value("STILLFRAME_DATASETS") or DATASETS_DIR) / RECORD

DT = 1 / 1024
#: the data file's size at most (the record, 8523 samples of 30 channels, takes 2 MB)
MAX_BYTES = 64 << 20
ORDER = 20
BLOCK_ROWS = 21
OUTPUTS = 4
MAX_OBSERVER_ORDER = 12
MAX_DAMPING = 0.2
OKID_METHODS = ("okid-era", "okid-eradc")


@dataclass(frozen=True)
class Model:
    """A discrete model from one method, with how long the identification took."""

    method: str
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    seconds: float
    observer_order: int | None = None
    warnings: tuple[str, ...] = ()
    """The quality checks of :mod:`stillframe.identification.quality` that failed (OKID methods
    only)."""


def load(path: str | Path | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Detrended inputs (N, 2) and outputs (N, 28) of the record at ``path`` (None:
    :func:`default_path`)."""
    path = Path(path) if path is not None else default_path()
    if not path.exists():
        raise InputError(f"DaISy file {path} not found (flexible_structure_dat.mat, DaISy 96-013; "
                         "give its path with --data)")
    try:
        with open_input(path, what="DaISy data file", max_bytes=MAX_BYTES) as stream:
            data = scipy.io.loadmat(stream)["flexible_structure_dat"]
    except (KeyError, ValueError, OSError) as exc:
        raise InputError(f"{path}: not the DaISy flexible-structure .mat file ({exc})") from None
    if data.ndim != 2 or data.shape[1] != 30:
        raise InputError(f"{path}: expected an N x 30 matrix, got {data.shape}")
    data = signal.detrend(np.asarray(data, dtype=float), axis=0)
    return data[:, :2], data[:, 2:]


def select_outputs(u: np.ndarray, y: np.ndarray, count: int = OUTPUTS) -> list[int]:
    """Indices of the ``count`` outputs with the highest mean multiple coherence."""
    coherence = h1_frf(u, y, DT, nperseg=256).coherence.mean(axis=0)
    return sorted(int(i) for i in np.argsort(coherence)[::-1][:count])


def mean_fit(model: Model, u: np.ndarray, y: np.ndarray) -> float:
    """Mean validation fit (%), or -inf for an unstable model."""
    try:
        return float(fit_percent(y, simulate_fitted(model.A, model.B, model.C, model.D, u, y))
                     .mean())
    except IdentificationError:
        return -math.inf


def okid_model(u: np.ndarray, y: np.ndarray, method: str, observer_order: int) -> Model:
    """The model of order :data:`ORDER` that ``method`` (an OKID variant of
    :func:`~stillframe.identification.pipeline.identify`, no refinement) identifies on ``u``, ``y``
    with observer order ``observer_order``, and the seconds it took."""
    start = time.perf_counter()
    ident = identify(u, y, DT, method, ORDER, observer_order=observer_order, refine=False)
    return Model(method, ident.A, ident.B, ident.C, ident.D, time.perf_counter() - start,
                 observer_order, ident.warnings)


def choose_observer_order(u: np.ndarray, y: np.ndarray, method: str) -> int:
    """p with the best fit on the last quarter of the identification half (see module doc)."""
    cut = 3 * len(u) // 4
    best, best_fit = None, -math.inf
    for p in range(math.ceil(ORDER / y.shape[1]), MAX_OBSERVER_ORDER + 1):
        try:
            model = okid_model(u[:cut], y[:cut], method, p)
        except (InputError, IdentificationError):
            continue
        fit = mean_fit(model, u[cut:], y[cut:])
        if fit > best_fit:
            best, best_fit = p, fit
    if best is None:
        raise InputError(f"{method}: no observer order gives a stable model on this record")
    return best


def output_error_model(start: Model, u: np.ndarray, y: np.ndarray) -> Model:
    """``start`` refined as an output-error model on ``u``, ``y`` (module docstring)."""
    begin = time.perf_counter()
    ref = refine_prediction_error(start.A, start.B, start.C, start.D,
                                  np.zeros((start.A.shape[0], y.shape[1])), u, y, DT,
                                  innovations=False)
    return Model(f"{start.method}-oe", ref.A, ref.B, ref.C, ref.D,
                 start.seconds + time.perf_counter() - begin, start.observer_order,
                 start.warnings)


def n4sid_model(u: np.ndarray, y: np.ndarray) -> Model:
    """The N4SID model of order :data:`ORDER` (:data:`BLOCK_ROWS` block rows) on ``u``, ``y``, and
    the seconds it took."""
    start = time.perf_counter()
    A, B, C, D = identify_n4sid(u, y, ORDER, BLOCK_ROWS)
    return Model("n4sid", A, B, C, D, time.perf_counter() - start)


def dominant_modes(model: Model) -> list[dict[str, float]]:
    """Modes (ζ < 0.2) with their peak modal contribution, largest first."""
    lam, psi = np.linalg.eig(model.A)
    w = np.linalg.inv(psi)
    peak = np.array([np.linalg.norm(np.outer(model.C @ psi[:, i], w[i] @ model.B))
                     / max(1 - abs(lam[i]), 1e-12) for i in range(lam.size)])
    modes = modal_parameters(model.A, model.C, DT)
    rows = []
    for f, z, lc in zip(modes.frequency_hz, modes.damping_ratio, modes.eigenvalues, strict=True):
        if not 0 < z < MAX_DAMPING:
            continue
        i = int(np.argmin(np.abs(np.log(lam) / DT - lc)))
        rows.append({"frequency_hz": float(f), "damping_ratio": float(z),
                     "peak": float(peak[i])})
    return sorted(rows, key=lambda r: -r["peak"])


def report(path: str | Path | None = None,
           progress: Callable[[str], None] = lambda _: None) -> dict:
    """Identify on the first half, validate on the second; everything the report prints."""
    u, y_all = load(path)
    half = len(u) // 2
    outputs = select_outputs(u[:half], y_all[:half])
    y = y_all[:, outputs]
    progress(f"outputs {[i + 1 for i in outputs]} of 28 (highest coherence)")
    models = []
    for method in OKID_METHODS:
        p = choose_observer_order(u[:half], y[:half], method)
        progress(f"{method}: observer order {p}")
        models.append(okid_model(u[:half], y[:half], method, p))
    progress("okid-era-oe: output-error refinement")
    models.append(output_error_model(models[0], u[:half], y[:half]))
    progress("n4sid")
    models.append(n4sid_model(u[:half], y[:half]))
    methods = {}
    for model in models:
        try:
            simulated = simulate_fitted(model.A, model.B, model.C, model.D, u[half:], y[half:])
            fit = fit_percent(y[half:], simulated).tolist()
        except IdentificationError:
            simulated, fit = None, None
        methods[model.method] = {
            "fit_percent": fit, "mean_fit_percent": float(np.mean(fit)) if fit else None,
            "seconds": model.seconds, "observer_order": model.observer_order,
            "modes": dominant_modes(model), "simulated": simulated,
            "warnings": list(model.warnings),
        }
    return {
        "dataset": "DaISy 96-013 steel subframe (flexible_structure_dat.mat)",
        "dt": DT, "order": ORDER, "n4sid_block_rows": BLOCK_ROWS,
        "outputs": [i + 1 for i in outputs],
        "samples": {"identification": half, "validation": len(u) - half},
        "methods": methods, "measured": y[half:],
    }


def match_dominant(reference: list[dict], other: list[dict], count: int) -> list[dict]:
    """For the ``count`` most dominant reference modes, the nearest mode of the other model."""
    rows = []
    for mode in reference[:count]:
        f = mode["frequency_hz"]
        near = min(other, key=lambda m: abs(m["frequency_hz"] - f))
        rows.append({"reference_hz": f, "other_hz": near["frequency_hz"],
                     "relative_difference": abs(near["frequency_hz"] - f) / f})
    return rows
