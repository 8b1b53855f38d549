"""The identification benchmark sweep : random shear buildings, three methods, errors.

A *case* is one random building, one record length, one signal-to-noise ratio and one seed.
:func:`run_case` simulates it and identifies it with stillframe's default path
(``identify(u, y, dt)``: OKID + ERA/DC, order ``auto``, then the prediction-error refinement,
which also gives 95 % intervals), the fast path without the refinement (``stillframe_okid``,
``refine=False``), N4SID (``nfoursid``, PO-MOESP) and python-control (``markov`` +
``eigensys_realization``); the last two are given the true order, stillframe chooses its own.
Output-only (the force unmeasured): stillframe's SSI-COV (order auto, jackknife intervals) and
pyOMA2's SSI-COV given the true order. :func:`run_cases` maps it over a list of cases (serially,
with progress); the function is top-level and picklable so a parallel executor can map it instead.

Buildings: a shear building of ``n`` storeys (2–5 modes) with random storey masses and
stiffnesses (±25 %) and modal damping ratios 1–5 %; in one case of two the top storey is replaced
by a tuned mass (mass ratio 2–5 %, tuned to the first mode), which splits the first mode into two
closely spaced ones. A white-noise force on floor 1, the accelerations of every mass measured,
zero-order hold at ``dt`` such that the highest mode lies at 0.2 of the sampling frequency, white
sensor noise at the given SNR (per channel, on the standard deviations).

Scoring: identified oscillatory modes are paired with the true ones by least relative frequency
distance (Hungarian assignment); a true mode without a partner within 5 % is *missed*. A run is
*wrong* when a mode is missed, or off by more than 1 % in frequency or 30 % in damping ratio; it
is *silently wrong* when, in addition, the method gave no warning (N4SID and python-control never
warn). A stillframe run is *silently worse than N4SID* when its worst frequency or damping error
exceeds 1.5 times N4SID's (and 0.1 % in frequency or 3 % in damping, a tenth of the wrong-run
limits) and it gave no warning. For the refined model, *coverage* counts the paired modes whose
true frequency (and damping ratio) lies inside its 95 % interval.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import control
import numpy as np
from numpy.typing import NDArray
from scipy import optimize, signal
from scipy.linalg import eigh

from stillframe.identification.modal import modal_parameters
from stillframe.identification.n4sid import identify_n4sid
from stillframe.identification.pipeline import identify
from stillframe.identification.ssi_cov import identify_output_only

Array = NDArray[np.float64]

SNR_DB: tuple[float, ...] = (40.0, 30.0, 20.0, 15.0, 10.0)
LENGTHS: tuple[int, ...] = (4096, 1024, 512, 256)
SEEDS = 10
QUICK_SNR_DB: tuple[float, ...] = (40.0, 15.0)
QUICK_LENGTHS: tuple[int, ...] = (1024, 256)
QUICK_SEEDS = 3
METHODS: tuple[str, ...] = ("stillframe", "stillframe_okid", "n4sid", "python_control",
                            "ssi_cov", "pyoma2_ssi_cov")
OUTPUT_ONLY: tuple[str, ...] = ("ssi_cov", "pyoma2_ssi_cov")
"""Methods given the outputs alone (the white force on floor 1 is then an unmeasured, ambient
excitation)."""
PYOMA2_BLOCK_ROWS = 20

FREQUENCY_LIMIT, DAMPING_LIMIT = 0.01, 0.30
"""A run is wrong beyond these relative errors."""
MISSED_DISTANCE = 0.05
"""A true mode whose paired identified mode is further than this (relative) is missed."""
N4SID_FACTOR = 1.5
"""A stillframe run whose worst error exceeds N4SID's by this factor must warn..."""
COMPARISON_FLOOR = 0.1
"""... unless the error is below this share of the wrong-run limits (0.1 % in frequency, 3 % in
damping): both methods are then right and the ratio of two small errors is noise."""
MARKOV_COUNT = 64
"""python-control: Markov parameters estimated (its ``markov`` cost grows fast with them)."""
TOP_MODE_FRACTION = 0.2
"""The highest true mode sits at this fraction of the sampling frequency."""


@dataclass(frozen=True)
class Case:
    """One run of the sweep: a building drawn from ``seed``, a record length and an SNR."""

    seed: int
    samples: int
    snr_db: float


@dataclass(frozen=True)
class Building:
    """A shear building's continuous model ``M q'' + C q' + K q = e_1 f`` and its true modes."""

    M: Array
    C: Array
    K: Array
    frequency_hz: Array
    damping_ratio: Array


def shear_building(seed: int) -> Building:
    """The random building of a seed (module docstring): 2–5 modes, every second seed with a
    tuned mass on top that makes the first mode a closely spaced pair."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 6))
    masses = rng.uniform(0.75, 1.25, n)
    stiffness = rng.uniform(0.75, 1.25, n) * 1000.0
    if n >= 2 and seed % 2 == 1:
        storeys = n - 1
        M0 = np.diag(masses[:storeys])
        K0 = _chain_stiffness(stiffness[:storeys])
        w2, phi = _eig(K0, M0)
        mu = rng.uniform(0.02, 0.05)
        modal_mass = float(phi[:, 0] @ M0 @ phi[:, 0]) / phi[-1, 0] ** 2
        masses[-1] = mu * modal_mass
        stiffness[-1] = masses[-1] * w2[0] / (1 + mu) ** 2  # Den Hartog's tuning
    M = np.diag(masses)
    K = _chain_stiffness(stiffness)
    w2, phi = _eig(K, M)
    omega = np.sqrt(w2)
    zeta = rng.uniform(0.01, 0.05, n)
    # modal damping: C = M Phi diag(2 zeta omega) Phi^T M with Phi^T M Phi = I
    C = M @ phi @ np.diag(2 * zeta * omega) @ phi.T @ M
    return Building(M=M, C=C, K=K, frequency_hz=omega / (2 * np.pi), damping_ratio=zeta)


def _chain_stiffness(k: Array) -> Array:
    n = k.size
    K = np.diag(k.copy())
    K[:-1, :-1] += np.diag(k[1:])
    for i in range(n - 1):
        K[i, i + 1] = K[i + 1, i] = -k[i + 1]
    return K


def _eig(K: Array, M: Array) -> tuple[Array, Array]:
    """Mass-normalised modes of ``K phi = w^2 M phi``, ascending."""
    return eigh(K, M)


@dataclass(frozen=True)
class Record:
    """One simulated record: the force ``u`` (N, 1), the accelerations ``y`` (N, n) and the sample
    period ``dt`` [s]."""

    u: Array
    y: Array
    dt: float


def simulate(building: Building, samples: int, snr_db: float, seed: int) -> Record:
    """ZOH simulation of the accelerations under a white force on floor 1, with sensor noise."""
    n = building.M.shape[0]
    Minv = np.linalg.inv(building.M)
    a_c = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ building.K, -Minv @ building.C]])
    b_c = np.vstack([np.zeros((n, 1)), Minv[:, :1]])
    c_c = np.hstack([-Minv @ building.K, -Minv @ building.C])
    d_c = Minv[:, :1]
    dt = TOP_MODE_FRACTION / float(building.frequency_hz.max())
    A, B, C, D, _ = signal.cont2discrete((a_c, b_c, c_c, d_c), dt, method="zoh")
    rng = np.random.default_rng(10_000 + seed)
    u = rng.standard_normal((samples, 1))
    x = np.zeros(2 * n)
    y = np.empty((samples, n))
    for k in range(samples):
        y[k] = C @ x + D @ u[k]
        x = A @ x + B @ u[k]
    noise = rng.standard_normal(y.shape) * y.std(axis=0) * 10 ** (-snr_db / 20)
    return Record(u=u, y=y + noise, dt=dt)


def score(frequency_hz: Array, damping_ratio: Array, true_frequency: Array, true_damping: Array,
          frequency_ci_hz: Array | None = None, damping_ci: Array | None = None) -> dict:
    """Pair the identified modes with the true ones and return the worst errors and flags (and,
    given the 95 % intervals, how many paired modes they cover)."""
    keep = (frequency_hz > 0) & np.isfinite(frequency_hz)
    f, z = frequency_hz[keep], damping_ratio[keep]
    covered = {"frequency": 0, "damping": 0, "paired": 0}
    n_true = true_frequency.size
    freq_err = np.full(n_true, math.inf)
    damp_err = np.full(n_true, math.inf)
    if f.size:
        cost = np.abs(f[None, :] - true_frequency[:, None]) / true_frequency[:, None]
        # capped, so that the assignment maximises the modes matched, not the far pairs' sum
        rows, cols = optimize.linear_sum_assignment(np.minimum(cost, 2 * MISSED_DISTANCE))
        for i, j in zip(rows, cols, strict=True):
            if cost[i, j] <= MISSED_DISTANCE:
                freq_err[i] = cost[i, j]
                damp_err[i] = abs(z[j] - true_damping[i]) / true_damping[i]
                if frequency_ci_hz is not None and damping_ci is not None:
                    f_lo, f_hi = frequency_ci_hz[keep][j]
                    z_lo, z_hi = damping_ci[keep][j]
                    covered["paired"] += 1
                    covered["frequency"] += int(f_lo <= true_frequency[i] <= f_hi)
                    covered["damping"] += int(z_lo <= true_damping[i] <= z_hi)
    missed = int(np.sum(~np.isfinite(freq_err)))
    wrong = bool(missed or np.any(freq_err > FREQUENCY_LIMIT) or np.any(damp_err > DAMPING_LIMIT))
    out = {"frequency_error": float(freq_err.max()), "damping_error": float(damp_err.max()),
           "missed": missed, "wrong": wrong}
    return out | ({"ci_covered": covered} if frequency_ci_hz is not None else {})


Identified = tuple[Array, Array, list[str], Array | None, Array | None]
"""Frequencies, damping ratios, warnings and (or None) the 95 % intervals."""


def _stillframe(record: Record, order: int) -> Identified:
    ident = identify(record.u, record.y, record.dt)
    ref = ident.refinement
    return (ident.modes.frequency_hz, ident.modes.damping_ratio, list(ident.warnings),
            ref.frequency_ci_hz, ref.damping_ci)


def _stillframe_okid(record: Record, order: int) -> Identified:
    ident = identify(record.u, record.y, record.dt, refine=False)
    return ident.modes.frequency_hz, ident.modes.damping_ratio, list(ident.warnings), None, None


def _n4sid(record: Record, order: int) -> Identified:
    m = record.y.shape[1]
    block_rows = max(math.ceil(order / m) + 1, min(10, record.u.shape[0] // 40))
    A, _, C, _ = identify_n4sid(record.u, record.y, order, block_rows)
    modes = modal_parameters(A, C, record.dt)
    return modes.frequency_hz, modes.damping_ratio, [], None, None


def _python_control(record: Record, order: int) -> Identified:
    count = min(MARKOV_COUNT, record.u.shape[0] // 8)
    markov = control.markov(record.y.T, record.u.T, count)
    sys_, _ = control.eigensys_realization(markov, order, dt=record.dt)
    modes = modal_parameters(sys_.A, sys_.C, record.dt)
    return modes.frequency_hz, modes.damping_ratio, [], None, None


def _ssi_cov(record: Record, order: int) -> Identified:
    ident = identify_output_only(record.y, record.dt)
    return (ident.modes.frequency_hz, ident.modes.damping_ratio, list(ident.warnings),
            ident.frequency_ci_hz, ident.damping_ci)


def _pyoma2_ssi_cov(record: Record, order: int) -> Identified:
    """pyOMA2's SSI-COV (its covariance Hankel matrix and shift-structure realization) at the
    true order; eigenvalues to modes with numpy here."""
    import logging
    import os

    os.environ.setdefault("TQDM_DISABLE", "1")  # pyOMA2's progress bars
    from pyoma2.functions.ssi import SSI, build_hank

    logging.getLogger("pyoma2").setLevel(logging.WARNING)  # and its per-call INFO lines (after
    # the import, which sets them up)

    block_rows = min(PYOMA2_BLOCK_ROWS, record.y.shape[0] // 8)
    hankel, _ = build_hank(record.y.T, record.y.T, block_rows, "cov")
    _, a_list, _ = SSI(hankel, block_rows, order)
    lam = np.log(np.linalg.eigvals(a_list[order]).astype(complex)) / record.dt
    lam = lam[lam.imag > 0]
    return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam), [], None, None


IDENTIFIERS: dict[str, Callable[[Record, int], Identified]] = {
    "stillframe": _stillframe, "stillframe_okid": _stillframe_okid, "n4sid": _n4sid,
    "python_control": _python_control, "ssi_cov": _ssi_cov, "pyoma2_ssi_cov": _pyoma2_ssi_cov,
}


def run_case(case: Case) -> dict:
    """Simulate one case and score every method on it (errors: worst over the modes; a method
    that raises counts as a refusal, which is a warning)."""
    building = shear_building(case.seed)
    record = simulate(building, case.samples, case.snr_db, case.seed)
    order = 2 * building.frequency_hz.size
    out: dict = {**asdict(case), "modes": int(building.frequency_hz.size),
                 "true_frequency_hz": building.frequency_hz.tolist(),
                 "true_damping_ratio": building.damping_ratio.tolist()}
    for name, identifier in IDENTIFIERS.items():
        try:
            f, z, warnings, f_ci, z_ci = identifier(record, order)
        except Exception as exc:  # a refusal or a failure of any method is scored
            out[name] = {"frequency_error": math.inf, "damping_error": math.inf,
                         "missed": int(building.frequency_hz.size), "wrong": True,
                         "warned": True, "silently_wrong": False,
                         "warnings": [f"refused: {exc}"]}
            continue
        result = score(f, z, building.frequency_hz, building.damping_ratio, f_ci, z_ci)
        result["warned"] = bool(warnings)
        result["silently_wrong"] = result["wrong"] and not warnings
        result["warnings"] = warnings
        out[name] = result
    for name in ("stillframe", "stillframe_okid"):
        out[name]["silently_worse_than_n4sid"] = (
            not out[name]["warned"] and worse_than(out[name], out["n4sid"]))
    return out


def worse_than(result: dict, reference: dict, factor: float = N4SID_FACTOR) -> bool:
    """Whether a run's worst frequency or damping error exceeds ``factor`` times the reference's
    and :data:`COMPARISON_FLOOR` of the wrong-run limit (a missed mode is an infinite error; two
    infinite errors are not worse)."""
    for key, limit in (("frequency_error", FREQUENCY_LIMIT), ("damping_error", DAMPING_LIMIT)):
        ours, theirs = result[key], reference[key]
        if math.isinf(ours) and not math.isinf(theirs):
            return True
        if math.isfinite(ours) and ours > factor * theirs and ours > COMPARISON_FLOOR * limit:
            return True
    return False


def cases(snr_db: Sequence[float], lengths: Sequence[int], seeds: int) -> list[Case]:
    """Every (SNR, length) cell with ``seeds`` buildings each (the same buildings in each cell)."""
    return [Case(seed=s, samples=n, snr_db=snr) for snr in snr_db for n in lengths
            for s in range(seeds)]


def run_cases(fn: Callable[[Case], dict], items: Sequence[Case], progress: bool = True
              ) -> list[dict]:
    """Map ``fn`` over the cases, serially, reporting progress on stderr (the one place to
    swap in a parallel executor)."""
    results = []
    for k, case in enumerate(items, 1):
        results.append(fn(case))
        if progress:
            print(f"\r{k}/{len(items)} cases", end="", file=sys.stderr, flush=True)
    if progress:
        print(file=sys.stderr)
    return results


def _quantile(values: list[float], q: float) -> float:
    """A quantile that is one of the values (so an infinite error stays infinite, not NaN)."""
    return float(np.quantile(np.asarray(values, dtype=float), q, method="inverted_cdf"))


def summarize(results: Sequence[dict]) -> list[dict]:
    """Per (SNR, length) cell and method: median and 90th-percentile worst-mode errors, wrong
    and silently wrong counts."""
    cells: dict[tuple[float, int], list[dict]] = {}
    for r in results:
        cells.setdefault((r["snr_db"], r["samples"]), []).append(r)
    table = []
    for (snr, n), runs in cells.items():
        row: dict = {"snr_db": snr, "samples": n, "runs": len(runs)}
        for name in METHODS:
            per = [r[name] for r in runs]
            fe = [p["frequency_error"] for p in per]
            de = [p["damping_error"] for p in per]
            row[name] = {
                "frequency_error_median": _quantile(fe, 0.5),
                "frequency_error_p90": _quantile(fe, 0.9),
                "damping_error_median": _quantile(de, 0.5),
                "damping_error_p90": _quantile(de, 0.9),
                "wrong": sum(p["wrong"] for p in per),
                "warned": sum(p["warned"] for p in per),
                "silently_wrong": sum(p["silently_wrong"] for p in per),
            }
            if "silently_worse_than_n4sid" in per[0]:
                row[name]["silently_worse_than_n4sid"] = sum(
                    p["silently_worse_than_n4sid"] for p in per)
            paired = sum(p.get("ci_covered", {}).get("paired", 0) for p in per)
            if paired:
                row[name]["ci_coverage_frequency"] = sum(
                    p["ci_covered"]["frequency"] for p in per if "ci_covered" in p) / paired
                row[name]["ci_coverage_damping"] = sum(
                    p["ci_covered"]["damping"] for p in per if "ci_covered" in p) / paired
        table.append(row)
    return table
