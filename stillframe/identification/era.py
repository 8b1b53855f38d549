"""Eigensystem realization: ERA (thesis eqs. 3.114–3.137) and ERA/DC (eqs. 3.138–3.164).

A Markov sequence is ``(K + 1, m, q)`` with entry ``k`` the parameter ``Y_k`` (``Y_0 = D``); q is
the number of columns of a parameter: r for system Markov parameters, ``r + m`` for the combined
parameters ``Gamma_k = [Y_k, Y^0_k]`` of eq. 3.165 (then the realized B is ``[B, G]``, eq. 3.169).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import IdentificationError, InputError

Array = NDArray[np.float64]

RANK_TOLERANCE = 1e-12
"""Singular values below this fraction of the largest count as zero (numerical rank)."""


@dataclass(frozen=True)
class Realization:
    """A discrete state-space model ``x(k+1) = A x + B u, y = C x + D u`` (eq. 3.137/3.164)."""

    A: Array
    B: Array
    C: Array
    D: Array


@dataclass(frozen=True)
class EraDimensions:
    """Block sizes: alpha block rows, beta block columns (eq. 3.114); for ERA/DC also gamma,
    delta correlation blocks and the lag tau (eq. 3.141)."""

    alpha: int
    beta: int
    gamma: int = 0
    delta: int = 0
    tau: int = 1

    def markov_count(self, correlated: bool) -> int:
        """How many parameters ``Y_0 .. Y_{K}`` the Hankel matrices use (K + 1)."""
        top_shift = (self.gamma + self.delta) * self.tau + 1 if correlated else 1
        return top_shift + self.alpha + self.beta


@dataclass(frozen=True)
class HankelFactorization:
    """The SVD of ``H(0)`` (ERA, eq. 3.122) or ``H_Delta(0)`` (ERA/DC, eq. 3.149) and the
    shifted matrix ``H(1)`` / ``H_Delta(1)``; :meth:`realize` truncates it to any order."""

    left: Array
    singular_values: Array
    right_t: Array
    shifted: Array
    hankel0: Array
    D: Array
    n_outputs: int
    n_columns: int
    alpha: int
    beta: int
    correlated: bool

    @property
    def max_rank(self) -> int:
        """``min(alpha m, beta q)``, the rank bound of ``H(0)``. (Markov parameters from OKID
        come from a model of order at most ``p m``, which bounds ERA/DC's matrices too.)"""
        return min(self.alpha * self.n_outputs, self.beta * self.n_columns)

    @property
    def numerical_rank(self) -> int:
        """The highest order :meth:`realize` accepts: the singular values above
        :data:`RANK_TOLERANCE` of the largest (:func:`numerical_rank`)."""
        return numerical_rank(self.singular_values)

    def realize(self, order: int) -> Realization:
        """Balanced realization of the given order (eq. 3.137, or 3.164 when correlated)."""
        if order < 1 or order > self.numerical_rank:
            raise InputError(
                f"model order {order} is outside 1..{self.numerical_rank} (the numerical rank "
                "of the Hankel matrix)"
            )
        s = self.singular_values[:order]
        r_n = self.left[:, :order]
        s_n = self.right_t[:order].T
        inv_sqrt = 1.0 / np.sqrt(s)
        A = (inv_sqrt[:, None] * (r_n.T @ self.shifted @ s_n)) * inv_sqrt[None, :]
        m, q = self.n_outputs, self.n_columns
        if self.correlated:
            p_alpha = r_n[: self.alpha * m] * np.sqrt(s)[None, :]  # eq. 3.157
            B = np.linalg.pinv(p_alpha) @ self.hankel0[:, :q]  # eq. 3.160, 3.162
            C = p_alpha[:m]  # eq. 3.161
        else:
            B = np.sqrt(s)[:, None] * s_n.T[:, :q]  # eq. 3.133
            C = r_n[:m] * np.sqrt(s)[None, :]  # eq. 3.132
        return Realization(A=A, B=B, C=C, D=self.D.copy())


def block_hankel(markov: Array, rows: int, cols: int, shift: int) -> Array:
    """``H(shift)`` of eq. 3.114: block (i, j) is ``Y_{1 + shift + i + j}``."""
    m, q = markov.shape[1:]
    need = shift + rows + cols
    if markov.shape[0] < need:
        raise InputError(
            f"{markov.shape[0]} Markov parameters given, the Hankel matrix needs {need}"
        )
    h = np.empty((rows * m, cols * q))
    for i in range(rows):
        h[i * m : (i + 1) * m] = np.hstack(list(markov[1 + shift + i : 1 + shift + i + cols]))
    return h


def factorize(markov: Array, dims: EraDimensions, correlated: bool) -> HankelFactorization:
    """Build the Hankel (or block correlation Hankel) matrices and take the SVD."""
    markov = np.asarray(markov, dtype=float)
    if markov.ndim != 3 or not np.all(np.isfinite(markov)):
        raise InputError("Markov parameters must be a finite (K + 1, m, q) array")
    if min(dims.alpha, dims.beta) < 1 or dims.tau < 1 or min(dims.gamma, dims.delta) < 0:
        raise InputError(f"invalid Hankel dimensions {dims}")
    m, q = markov.shape[1:]
    h0 = block_hankel(markov, dims.alpha, dims.beta, 0)
    if correlated:
        lags = (dims.gamma + dims.delta) * dims.tau + 2
        delta = [block_hankel(markov, dims.alpha, dims.beta, k) @ h0.T for k in range(lags)]

        def correlation_hankel(k: int) -> Array:  # eqs. 3.141, 3.145, 3.146
            return np.block([[delta[k + (i + j) * dims.tau] for j in range(dims.delta + 1)]
                             for i in range(dims.gamma + 1)])

        base, shifted = correlation_hankel(0), correlation_hankel(1)
    else:
        base, shifted = h0, block_hankel(markov, dims.alpha, dims.beta, 1)
    left, s, right_t = np.linalg.svd(base, full_matrices=False)
    return HankelFactorization(
        left=left, singular_values=s, right_t=right_t, shifted=shifted, hankel0=h0,
        D=markov[0].copy(), n_outputs=m, n_columns=q, alpha=dims.alpha, beta=dims.beta,
        correlated=correlated,
    )


def numerical_rank(singular_values: Array) -> int:
    """Singular values above :data:`RANK_TOLERANCE` of the largest (descending order)."""
    s = singular_values
    return int(np.sum(s > RANK_TOLERANCE * s[0])) if s.size and s[0] > 0 else 0


def auto_order(singular_values: Array, max_order: int) -> tuple[int, float]:
    """Order at the largest relative gap ``sigma_n / sigma_{n+1}`` for n in 1..max_order.

    Singular values below the rank tolerance count as the tolerance (so noise-free data give a
    finite gap at their exact order). Keep ``max_order`` well below the Hankel matrix's size
    (:attr:`HankelFactorization.max_rank`): noisy singular values fall to numerical zero there,
    which is no model order. Returns the order and the gap.
    """
    s = np.asarray(singular_values, dtype=float)
    if s.size < 2 or s[0] <= 0:
        raise IdentificationError(
            "need at least two non-zero Hankel singular values to choose an order")
    floor = RANK_TOLERANCE * s[0]
    last = min(max_order, s.size - 1)
    ratios = [s[n - 1] / max(s[n], floor) for n in range(1, last + 1) if s[n - 1] > floor]
    if not ratios:
        raise IdentificationError("no usable Hankel singular values to choose an order")
    best = int(np.argmax(ratios))
    return best + 1, float(ratios[best])


def order_gap(singular_values: Array, order: int) -> float:
    """The relative gap ``sigma_n / sigma_{n+1}`` at a given order (inf when sigma_{n+1} = 0)."""
    s = np.asarray(singular_values, dtype=float)
    if order >= s.size:
        return float("inf")
    return float(s[order - 1] / s[order]) if s[order] > 0 else float("inf")
