"""Compiled one-step predictor of an innovation-form model, batched over parameter vectors.

The predictor of ``x(k+1) = A x + B u + K e, y = C x + D u + e`` (Ljung, *System
Identification*, 2nd ed. 1999, eq. 4.86):

    x̂(k+1) = Ā x̂(k) + B̄ w(k),    e(k) = y(k) - C x̂(k) - D u(k),

with ``Ā = A - K C``, ``B̄ = [B - K D, K]`` and ``w(k) = [u(k); y(k)]``. One call runs it for a
batch of models (the finite-difference Jacobian of :mod:`stillframe.identification.pem` perturbs one
parameter per batch entry), without Python overhead per sample.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


@numba.njit(cache=True)
def _errors(abar: Array, bbar: Array, C: Array, D: Array, x0: Array, u: Array, y: Array,
            out: Array) -> None:
    batch, n = x0.shape
    samples, m = y.shape
    r = u.shape[1]
    x = np.empty(n, dtype=out.dtype)
    nxt = np.empty(n, dtype=out.dtype)
    for b in range(batch):
        x[:] = x0[b]
        for k in range(samples):
            for i in range(m):
                s = y[k, i]
                for j in range(n):
                    s -= C[b, i, j] * x[j]
                for j in range(r):
                    s -= D[b, i, j] * u[k, j]
                out[b, k, i] = s
            for i in range(n):
                s = abar[b, i, 0] * 0.0
                for j in range(n):
                    s += abar[b, i, j] * x[j]
                for j in range(r):
                    s += bbar[b, i, j] * u[k, j]
                for j in range(m):
                    s += bbar[b, i, r + j] * y[k, j]
                nxt[i] = s
            x[:] = nxt


def prediction_errors(A: Array, B: Array, C: Array, D: Array, K: Array, x0: Array, u: Array,
                      y: Array) -> Array:
    """One-step prediction errors ``e (b, N, m)`` of the models ``A (b, n, n)``, ``B (b, n, r)``,
    ``C (b, m, n)``, ``D (b, m, r)``, ``K (b, n, m)`` from ``x0 (b, n)`` on ``u (N, r)``,
    ``y (N, m)``."""
    abar = A - K @ C
    bbar = np.concatenate([B - K @ D, K], axis=2)
    dtype = np.result_type(abar, bbar, C, D, x0, u, y)
    out = np.empty((x0.shape[0], y.shape[0], y.shape[1]), dtype=dtype)
    with np.errstate(over="ignore", invalid="ignore"):
        _errors(np.ascontiguousarray(abar), np.ascontiguousarray(bbar), np.ascontiguousarray(C),
                np.ascontiguousarray(D), np.ascontiguousarray(x0), np.ascontiguousarray(u),
                np.ascontiguousarray(y), out)
    return out
