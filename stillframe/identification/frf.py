"""Frequency response functions by the H1 estimator, with multiple coherence (thesis §5.5 uses
auto- and cross-spectral densities of the hammer records).

For r inputs and m outputs at each frequency: ``H1 = G_yu G_uu^-1`` (m x r), with ``G_yu[i, j]``
the cross-spectral density from input j to output i and ``G_uu`` the input spectral matrix
(Welch averages, :func:`scipy.signal.csd`). The multiple coherence of output i is
``(H1 G_uu H1^H)_ii / G_yy,ii``, which for one input is the ordinary coherence
``|G_yu|^2 / (G_uu G_yy)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from stillframe.errors import IdentificationError, InputError

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Frf:
    """``frequency_hz (F,)``, ``H (F, m, r)`` complex, ``coherence (F, m)`` and the number of
    Welch segments averaged (with one, the coherence is 1 identically and says nothing)."""

    frequency_hz: Array
    H: NDArray[np.complex128]
    coherence: Array
    segments: int = 0


MIN_SEGMENTS = 8
"""Welch segments :func:`segment_length` aims at, so that the coherence is an estimate."""


def welch_segments(samples: int, nperseg: int) -> int:
    """Segments scipy's Welch estimate averages with its default half overlap."""
    step = nperseg - nperseg // 2
    return (samples - nperseg) // step + 1


def segment_length(samples: int, longest: int = 256) -> int:
    """The largest power of two up to ``longest`` giving at least :data:`MIN_SEGMENTS` segments
    (at least 8 samples; fewer segments for records too short for that)."""
    n = 8
    while 2 * n <= longest and welch_segments(samples, 2 * n) >= MIN_SEGMENTS:
        n *= 2
    return min(n, samples)


def h1_frf(u: Array, y: Array, dt: float, nperseg: int = 256, window: str = "hann") -> Frf:
    """H1 estimate from inputs ``u (N, r)`` and outputs ``y (N, m)`` sampled at ``dt``."""
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    u = u[:, None] if u.ndim == 1 else u
    y = y[:, None] if y.ndim == 1 else y
    if u.shape[0] != y.shape[0]:
        raise InputError(f"input has {u.shape[0]} samples but output has {y.shape[0]}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise InputError("FRF records contain NaN or inf")
    if dt <= 0:
        raise InputError(f"sampling interval must be positive, got {dt}")
    if nperseg < 8 or nperseg > u.shape[0]:
        raise InputError(f"segment length {nperseg} must be within 8..{u.shape[0]} samples")
    fs = 1.0 / dt
    r, m = u.shape[1], y.shape[1]

    def spectrum(a: Array, b: Array) -> tuple[Array, Array]:
        return signal.csd(a, b, fs=fs, window=window, nperseg=nperseg)

    freq, _ = spectrum(u[:, 0], u[:, 0])
    g_uu = np.empty((freq.size, r, r), dtype=complex)
    g_yu = np.empty((freq.size, m, r), dtype=complex)
    g_yy = np.empty((freq.size, m))
    for j in range(r):
        for k in range(r):
            g_uu[:, j, k] = spectrum(u[:, k], u[:, j])[1]  # E[U_j U_k^*]
        for i in range(m):
            g_yu[:, i, j] = spectrum(u[:, j], y[:, i])[1]  # E[Y_i U_j^*]
    for i in range(m):
        g_yy[:, i] = spectrum(y[:, i], y[:, i])[1].real
    conds = np.linalg.cond(g_uu)
    if not np.all(np.isfinite(conds)) or np.any(conds > 1e12):
        raise IdentificationError(
            "input spectral matrix is singular at some frequency: the inputs do not "
                         "excite all frequencies independently")
    H = np.linalg.solve(g_uu.transpose(0, 2, 1), g_yu.transpose(0, 2, 1)).transpose(0, 2, 1)
    explained = np.einsum("fij,fjk,fik->fi", H, g_uu, H.conj()).real
    coherence = np.divide(explained, g_yy, out=np.zeros_like(g_yy), where=g_yy > 0)
    return Frf(frequency_hz=freq, H=H, coherence=np.clip(coherence, 0.0, 1.0),
               segments=welch_segments(u.shape[0], nperseg))


def model_frf(A: Array, B: Array, C: Array, D: Array, dt: float, frequency_hz: Array,
              ) -> NDArray[np.complex128]:
    """``C (z I - A)^-1 B + D`` at ``z = exp(i 2 pi f dt)``, shape ``(F, m, r)`` (for overlays)."""
    z = np.exp(1j * 2.0 * np.pi * np.asarray(frequency_hz) * dt)
    n = A.shape[0]
    out = np.empty((z.size, C.shape[0], B.shape[1]), dtype=complex)
    for k, zk in enumerate(z):
        out[k] = C @ np.linalg.solve(zk * np.eye(n) - A, B) + D
    return out
