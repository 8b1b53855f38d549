"""Output-only identification (operational modal analysis): covariance-driven stochastic subspace
identification, SSI-COV (Peeters & De Roeck 1999; Reynders 2012, §3.2).

For outputs ``y (N, m)`` driven by an unmeasured broadband excitation (ambient, or a force nobody
recorded), each channel divided by its RMS first (the modes do not depend on the units):

1. output covariances ``R_i = 1/(N − i) Σ_k y(k + i) y(k)ᵀ``, i = 1 … 2 p − 1 (all outputs are
   references);
2. the block Toeplitz matrix ``T = [R_{p+a−b}]_{a,b = 0..p−1}`` (``p m × p m``) = ``O_p C_p``,
   observability times reversed controllability; its SVD ``T = U S Vᵀ``;
3. at order n: ``O = U_n S_n^{1/2}``, ``C`` its first m rows and ``A = O_↑⁺ O_↓`` (the shift
   structure); the modes of ``(A, C)`` as for the input–output methods
   (:func:`stillframe.identification.modal.modal_parameters`), shapes scaled back to the units.

The order: ``"auto"`` takes the largest singular-value gap of T up to ``max_order``, as ERA does.
The same checks as :func:`stillframe.identification.pipeline.identify`: each channel refused when
constant or non-finite (:mod:`stillframe.identification.data_checks`), the record when too short
for p; warnings for a weak gap, modes that are not consistent at orders n + 2 and n + 4, modes
with negative damping, and modes whose 95 % interval is wide.

**Intervals**: a delete-one-block jackknife (Efron & Tibshirani 1993, §11): the record's
covariances are sums over :data:`JACKKNIFE_BLOCKS` consecutive blocks; leaving each out in turn
gives that many estimates at the same order, matched to the full one by frequency (and MAC), and
``σ² = (B − 1)/B Σ (θ_b − θ̄)²``; the interval is ``θ ± 1.96 σ``. (Reynders, Pintelon & De Roeck
2008 propagate the covariance of T to first order instead; the jackknife needs no derivatives
and, like their method, reads the variance off the record's own segments.) A mode with no match
in a leave-one-out estimate gets an infinite interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import IdentificationError, InputError
from stillframe.identification.data_checks import (
    channel_names,
    channel_scales,
    check_length,
    check_values,
)
from stillframe.identification.era import auto_order, numerical_rank, order_gap
from stillframe.identification.modal import ModalTable, mac, modal_parameters
from stillframe.identification.quality import quality_warnings, uncertain_modes
from stillframe.identification.stabilization import matching_modes

__all__ = ["OutputOnlyIdentification", "SsiRealization", "ToeplitzFactorization", "factorize",
           "identify_output_only", "minimum_samples"]

Array = NDArray[np.float64]

OUTPUT_ONLY_METHODS: tuple[str, ...] = ("ssi-cov",)
DEFAULT_BLOCK_ROWS = 20
"""p, the Toeplitz matrix's block rows (lowered for short records); orders up to p m."""
JACKKNIFE_BLOCKS = 10
"""Blocks of the record left out one at a time for the intervals."""
Z95 = 1.959963984540054


@dataclass(frozen=True)
class SsiRealization:
    """A and C of one order."""

    A: Array
    C: Array


@dataclass(frozen=True)
class ToeplitzFactorization:
    """The SVD of the output covariances' block Toeplitz matrix; :meth:`realize` gives any order
    (the interface :func:`stillframe.identification.stabilization.stabilization_diagram` uses)."""

    left: Array
    singular_values: Array
    n_outputs: int

    @property
    def numerical_rank(self) -> int:
        """The highest order :meth:`realize` accepts: the singular values above the tolerance of
        :func:`~stillframe.identification.era.numerical_rank`."""
        return numerical_rank(self.singular_values)

    def realize(self, order: int) -> SsiRealization:
        """The (A, C) of order ``order``: the observability matrix from the leading singular vectors
        scaled by the square roots of their values, C its first block row, A by least squares from
        its shift; :class:`~stillframe.errors.InputError` outside 1 … :attr:`numerical_rank`."""
        if order < 1 or order > self.numerical_rank:
            raise InputError(f"model order {order} is outside 1..{self.numerical_rank} (the "
                             "numerical rank of the output covariances' Toeplitz matrix)")
        m = self.n_outputs
        obs = self.left[:, :order] * np.sqrt(self.singular_values[:order])
        A = np.linalg.lstsq(obs[:-m], obs[m:], rcond=None)[0]
        return SsiRealization(A=A, C=obs[:m])


@dataclass(frozen=True)
class OutputOnlyIdentification:
    """SSI-COV's model, modes with 95 % intervals, and its checks."""

    A: Array
    C: Array
    """In the outputs' units."""
    dt: float
    order: int
    order_gap: float
    singular_values: Array
    block_rows: int
    modes: ModalTable
    consistent: NDArray[np.bool_]
    frequency_ci_hz: Array
    damping_ci: Array
    warnings: tuple[str, ...]
    factorization: ToeplitzFactorization
    method: str = "ssi-cov"

    @property
    def auto_mac(self) -> Array:
        """MAC between every pair of the identified modes (near 0 off the diagonal when the
        sensors tell the modes apart)."""
        return mac(self.modes.shapes, self.modes.shapes)


def _covariance_sums(y: Array, lags: int, start: int = 0, stop: int | None = None
                     ) -> tuple[Array, Array]:
    """``Σ_k y(k + i) y(k)ᵀ`` over k in ``[start, stop)`` for i = 0 … lags − 1, and the counts."""
    n = y.shape[0]
    stop = n if stop is None else stop
    sums = np.empty((lags, y.shape[1], y.shape[1]))
    counts = np.empty(lags)
    for i in range(lags):
        hi = min(stop, n - i)
        sums[i] = y[start + i: hi + i].T @ y[start: hi] if hi > start else 0.0
        counts[i] = max(hi - start, 0)
    return sums, counts


def _toeplitz(cov: Array, p: int) -> Array:
    """``[R_{p+a−b}]`` for a, b = 0 … p − 1 (``cov[i]`` = R_i)."""
    m = cov.shape[1]
    out = np.empty((p * m, p * m))
    for a in range(p):
        for b in range(p):
            out[a * m:(a + 1) * m, b * m:(b + 1) * m] = cov[p + a - b]
    return out


def factorize(cov: Array, p: int) -> ToeplitzFactorization:
    """The SVD of the block Toeplitz matrix ``[R_{p+a−b}]`` (a, b = 0 … p − 1) of the output
    covariances ``cov`` (``cov[i]`` = R_i, i up to 2p − 1 used)."""
    left, s, _ = np.linalg.svd(_toeplitz(cov, p))
    return ToeplitzFactorization(left=left, singular_values=s, n_outputs=cov.shape[1])


def _block_rows(n_samples: int, m: int, order: int, requested: int | None) -> int:
    if requested is not None:
        if requested * m < order:
            raise InputError(f"block rows {requested} with {m} outputs bound the order by "
                             f"{requested * m} < {order}")
        return requested
    p = DEFAULT_BLOCK_ROWS
    while p > max(1, math.ceil(order / m) + 1) and minimum_samples(p) > n_samples:
        p -= 1
    return max(p, math.ceil(order / m) + 1)


def minimum_samples(p: int) -> int:
    """Samples for the 2 p lags with at least :data:`JACKKNIFE_BLOCKS` blocks of 4 p samples."""
    return 4 * p * JACKKNIFE_BLOCKS


def _jackknife(y: Array, p: int, order: int, dt: float, reference: ModalTable
               ) -> tuple[Array, Array]:
    """Delete-one-block jackknife intervals (module docstring) for ``reference``'s modes."""
    n = y.shape[0]
    edges = np.linspace(0, n, JACKKNIFE_BLOCKS + 1).astype(int)
    total, counts = _covariance_sums(y, 2 * p)
    k = len(reference)
    f = np.full((JACKKNIFE_BLOCKS, k), np.nan)
    z = np.full((JACKKNIFE_BLOCKS, k), np.nan)
    for b in range(JACKKNIFE_BLOCKS):
        part, part_counts = _covariance_sums(y, 2 * p, edges[b], edges[b + 1])
        cov = (total - part) / (counts - part_counts)[:, None, None]
        fac = factorize(cov, p)
        if fac.numerical_rank < order:
            continue
        real = fac.realize(order)
        modes = modal_parameters(real.A, real.C, dt)
        for j in range(k):
            if not len(modes):
                break
            d = np.abs(modes.frequency_hz - reference.frequency_hz[j])
            best = int(np.argmin(d))
            if d[best] <= 0.05 * reference.frequency_hz[j]:
                f[b, j], z[b, j] = modes.frequency_hz[best], modes.damping_ratio[best]
    blocks = JACKKNIFE_BLOCKS

    def interval(samples: Array, centre: Array) -> Array:
        complete = np.all(np.isfinite(samples), axis=0)
        spread = np.sqrt((blocks - 1) / blocks
                         * np.nansum((samples - np.nanmean(samples, axis=0)) ** 2, axis=0))
        half = np.where(complete, Z95 * spread, np.inf)
        return np.column_stack([centre - half, centre + half])

    return interval(f, reference.frequency_hz), interval(z, reference.damping_ratio)


def identify_output_only(
    y: Array,
    dt: float,
    order: int | Literal["auto"] = "auto",
    *,
    max_order: int | None = None,
    block_rows: int | None = None,
    output_names: list[str] | None = None,
) -> OutputOnlyIdentification:
    """SSI-COV (module docstring) on outputs ``y (N, m)`` sampled at ``dt``."""
    y = np.asarray(y, dtype=float)
    y = y[:, None] if y.ndim == 1 else y
    if y.ndim != 2 or y.shape[0] == 0 or y.shape[1] == 0:
        raise InputError(f"output must be a non-empty (samples, channels) array, got {y.shape}")
    if isinstance(dt, bool) or not (isinstance(dt, (int, float)) and math.isfinite(dt)
                                    and dt > 0):
        raise InputError(f"sampling interval dt must be a positive number, got {dt!r}")
    if order != "auto" and (isinstance(order, bool) or not isinstance(order, int) or order < 1):
        raise InputError(f"order must be a positive integer or 'auto', got {order!r}")
    n_samples, m = y.shape
    names = channel_names("output", m, output_names)
    check_values(y, names)
    needed = 2 if order == "auto" else int(order)
    p = _block_rows(n_samples, m, needed, block_rows)
    check_length(n_samples, minimum_samples(p), needed, names,
                 f"SSI-COV with {p} block rows and {JACKKNIFE_BLOCKS} jackknife blocks")
    scale = channel_scales(y)
    y = y / scale
    sums, counts = _covariance_sums(y, 2 * p)
    fac = factorize(sums / counts[:, None, None], p)
    s = fac.singular_values
    if order == "auto":
        chosen, gap = auto_order(s, max_order or max(2, fac.numerical_rank // 2))
    else:
        chosen, gap = needed, order_gap(s, needed)
    if chosen > fac.numerical_rank:
        raise IdentificationError(f"order {chosen} above the numerical rank "
                                  f"{fac.numerical_rank} of the output covariances")
    real = fac.realize(chosen)
    modes = modal_parameters(real.A, real.C, dt)
    consistent = np.ones(len(modes), dtype=bool)
    for step in (2, 4):
        if chosen + step <= fac.numerical_rank:
            larger = fac.realize(chosen + step)
            consistent &= matching_modes(modes, modal_parameters(larger.A, larger.C, dt), 0.01,
                                         0.2, 0.9)[1]
    f_ci, z_ci = _jackknife(y, p, chosen, dt, modes)
    uncertain = uncertain_modes(modes, f_ci, z_ci)
    C = scale[:, None] * real.C
    physical = modal_parameters(real.A, C, dt)
    warnings = quality_warnings(modes, consistent, chosen, gap, np.empty(0), uncertain)
    return OutputOnlyIdentification(
        A=real.A, C=C, dt=float(dt), order=chosen, order_gap=gap, singular_values=s,
        block_rows=p, modes=physical, consistent=consistent, frequency_ci_hz=f_ci,
        damping_ci=z_ci, warnings=tuple(warnings), factorization=fac)
