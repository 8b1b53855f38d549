"""Observer/Kalman filter identification (OKID), thesis §3.4–3.5.

Array conventions used throughout :mod:`identification`: ``u`` is ``(N, r)`` (N samples of r
inputs), ``y`` is ``(N, m)``; a Markov sequence is ``(K + 1, m, r)`` with entry ``k`` the
parameter ``Y_k`` of eq. 3.73 (``Y_0 = D``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import IdentificationError, InputError

__all__ = ["OkidResult", "minimum_samples", "observer_gain", "okid"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class OkidResult:
    """Observer Markov parameters and what follows from them (eqs. 3.104, 3.107, 3.108)."""

    observer_markov: Array
    """``(p + 1, m, r + m)``: ``Ybar_0 .. Ybar_p`` of eq. 3.104 (``Ybar_0 = [D, 0]``)."""
    observer_order: int
    """p, the number of observer Markov parameters (eq. 3.97)."""
    residual_rms: Array
    """``(m,)`` root-mean-square one-step ARX prediction error of each output."""

    @property
    def feedthrough(self) -> Array:
        """D = Ybar_0 (eq. 3.107)."""
        return self.observer_markov[0, :, : self.n_inputs]

    @property
    def n_inputs(self) -> int:
        """r, the number of inputs: the observer Markov parameters' columns are r inputs, then m
        outputs."""
        return self.observer_markov.shape[2] - self.observer_markov.shape[1]

    def system_markov(self, count: int) -> Array:
        """``Y_0 .. Y_{count-1}`` by the recursion of eq. 3.107, shape ``(count, m, r)``."""
        r, p = self.n_inputs, self.observer_order
        ybar1 = self.observer_markov[:, :, :r]
        ybar2 = -self.observer_markov[:, :, r:]  # eq. 3.87: Ybar_k = [Ybar1_k, -Ybar2_k]
        m = ybar2.shape[1]
        out = np.zeros((count, m, r))
        out[0] = self.feedthrough
        for k in range(1, count):
            acc = ybar1[k].copy() if k <= p else np.zeros((m, r))
            for j in range(1, min(k, p) + 1):
                acc -= ybar2[j] @ out[k - j]
            out[k] = acc
        return out

    def observer_gain_markov(self, count: int) -> Array:
        """``Y^0_0 .. Y^0_{count-1}`` of eq. 3.108 (``Y^0_0 = 0``), shape ``(count, m, m)``."""
        r, p = self.n_inputs, self.observer_order
        ybar2 = -self.observer_markov[:, :, r:]
        m = ybar2.shape[1]
        out = np.zeros((count, m, m))
        for k in range(1, count):
            acc = ybar2[k].copy() if k <= p else np.zeros((m, m))
            for j in range(1, min(k - 1, p) + 1):
                acc -= ybar2[j] @ out[k - j]
            out[k] = acc
        return out


def minimum_samples(n_inputs: int, n_outputs: int, observer_order: int) -> int:
    """Samples needed for an over-determined least-squares fit of eq. 3.106."""
    unknowns = n_inputs + (n_inputs + n_outputs) * observer_order
    return observer_order + unknowns + 1


def okid(u: Array, y: Array, observer_order: int) -> OkidResult:
    """Observer Markov parameters by least squares, ``Lbar_p = Y V_p^+`` (eqs. 3.102–3.106).

    The first ``p`` columns of eq. 3.105 are dropped, so the record need not start at rest.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    n, r = u.shape
    m = y.shape[1]
    p = int(observer_order)
    if p < 1:
        raise InputError(f"observer order must be >= 1, got {p}")
    if n < minimum_samples(r, m, p):
        raise IdentificationError(
            f"record of {n} samples too short for observer order {p} with {r} inputs and "
            f"{m} outputs (needs at least {minimum_samples(r, m, p)})"
        )
    v = np.hstack([u, y])
    rows = [u[p:]]
    for j in range(1, p + 1):
        rows.append(v[p - j : n - j])
    regressors = np.hstack(rows)  # (cols, r + (r + m) p), the transpose of V_p
    target = y[p:]
    coef, *_ = np.linalg.lstsq(regressors, target, rcond=None)
    residual = target - regressors @ coef
    lbar = coef.T  # (m, r + (r+m) p), eq. 3.104
    observer_markov = np.zeros((p + 1, m, r + m))
    observer_markov[0, :, :r] = lbar[:, :r]
    for j in range(1, p + 1):
        start = r + (j - 1) * (r + m)
        observer_markov[j] = lbar[:, start : start + r + m]
    return OkidResult(
        observer_markov=observer_markov,
        observer_order=p,
        residual_rms=np.sqrt(np.mean(residual**2, axis=0)),
    )


def observer_gain(A: Array, C: Array, gain_markov: Array) -> Array:
    """Observer gain G from ``Y^0_1 .. Y^0_p`` by least squares, ``G = P_p^+ Y^0_p`` (3.109–3.112).

    ``gain_markov`` is ``(p + 1, m, m)`` as returned by :meth:`OkidResult.observer_gain_markov`.
    """
    p = gain_markov.shape[0] - 1
    blocks = [C]
    for _ in range(1, p):
        blocks.append(blocks[-1] @ A)
    obs = np.vstack(blocks)
    rhs = np.vstack(list(gain_markov[1:]))
    gain, *_ = np.linalg.lstsq(obs, rhs, rcond=None)
    return gain
