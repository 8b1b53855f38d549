"""Checks of the records before anything is identified, and the scaling that makes identification
independent of the units the data come in.

Each check refuses with :class:`~stillframe.errors.IdentificationError` (exit code 5) and names the
channel at fault (``TOPIC:FIELD`` when the record came from a bag):

- a non-finite value (the sample's index is given);
- a constant channel, all zero included: the peak-to-peak range is at most
  :data:`CONSTANT_TOLERANCE` of the largest magnitude (relative, so a channel in any units passes
  or fails alike);
- more than one sample in :data:`ABSURD_SHARE` of a channel that no physical signal makes
  (:func:`absurd_samples`: robust statistics, median and MAD of the channel and of its first
  difference); fewer are replaced by linear interpolation and named (channel, time, value) in a
  warning, so the record stays a uniformly sampled series for the state-space methods;
- a record too short for the order asked (the caller gives the samples the method needs);
- an input that is not persistently exciting of the model order ``n`` (Ljung 1999, §13.2): the
  sample covariance of ``n`` successive input samples, ``R_n = Φᵀ Φ / N`` with
  ``Φ(k) = [u(k)ᵀ … u(k − n + 1)ᵀ]``, must be non-singular, i.e. its smallest eigenvalue above
  :data:`EXCITATION_TOLERANCE` of its largest. An input of ``s`` sinusoids is persistently
  exciting of order ``2 s`` and drives at most ``s`` modes, ``2 s`` states; a model of a larger
  order would fit the noise in the directions the input leaves out. With several inputs each is
  checked alone first (so the message names it), then together (inputs that are copies of each
  other are named together).

:func:`channel_scales` gives each channel's scale (its RMS, computed without overflow or
underflow); :func:`stillframe.identification.pipeline.identify` divides the records by it before
identifying and scales B, C, D and the observer gain back, so data scaled by 1e-300 … 1e300 give the
same modes (the eigenvalues of A do not depend on the units of u and y).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import IdentificationError

Array = NDArray[np.float64]

CONSTANT_TOLERANCE = 1e-12
"""A channel whose peak-to-peak range is at most this share of its largest magnitude is constant."""
ABSURD_FACTOR = 1e8
"""A sample this many robust scales from its channel's median, and as many of its first
difference's from its neighbours, is absurd: beyond the dynamic range of any converter over its
noise floor (a 24-bit converter spans 2^24 ≈ 1.7e7 steps), so a fault (a flipped bit, a
corrupt record), not a signal. A hammer blow stands a few thousand noise levels above the rest."""
ABSURD_SHARE = 1000
"""At most one sample in this many per channel is replaced by interpolation; more are refused."""
EXCITATION_TOLERANCE = 1e-10
"""Smallest eigenvalue of the input covariance ``R_n``, relative to its largest, accepted."""


def channel_names(prefix: str, count: int, names: Sequence[str] | None) -> list[str]:
    """The names given, or ``input 1``, ``input 2`` … when none are."""
    if names is None:
        return [f"{prefix} {i + 1}" for i in range(count)]
    if len(names) != count:
        raise IdentificationError(f"{len(names)} {prefix} names given for {count} {prefix} "
                                  "channels")
    return [str(n) for n in names]


def channel_scales(data: Array) -> Array:
    """Each column's RMS, as ``peak · rms(column / peak)`` so that values near the float range's
    ends neither overflow nor underflow when squared; 1 for an all-zero column."""
    peak = np.max(np.abs(data), axis=0)
    safe = np.where(peak > 0, peak, 1.0)
    rms = safe * np.sqrt(np.mean((data / safe) ** 2, axis=0))
    return np.where(rms > 0, rms, 1.0)


def check_values(data: Array, names: Sequence[str]) -> None:
    """Refuse a channel with a non-finite value, or one that is constant (all zero included)."""
    for j, name in enumerate(names):
        column = data[:, j]
        bad = np.flatnonzero(~np.isfinite(column))
        if bad.size:
            raise IdentificationError(f"channel {name}: non-finite value {column[bad[0]]} in "
                                      f"sample {int(bad[0])}")
        peak = float(np.max(np.abs(column)))
        if peak == 0.0:
            raise IdentificationError(f"channel {name} is all zero: it carries no information "
                                      "(wrong field, or a sensor or actuator not connected?)")
        if float(np.ptp(column)) <= CONSTANT_TOLERANCE * peak:
            raise IdentificationError(f"channel {name} is constant ({column[0]:.6g}): it carries "
                                      "no information")


def absurd_samples(column: Array) -> NDArray[np.int_]:
    """Indices of samples that no physical signal makes (module docstring): beyond
    :data:`ABSURD_FACTOR` robust scales (1.4826 · MAD) of the channel from its median, and
    beyond as many of its first difference's from the neighbouring samples. A channel whose MAD
    is zero (a pulse on zeros) has no robust scale and is not judged."""
    dev = np.abs(column - np.median(column))
    scale = 1.4826 * np.median(dev)
    diff = np.diff(column)
    diff_scale = 1.4826 * np.median(np.abs(diff - np.median(diff)))
    if not (scale > 0 and diff_scale > 0):
        return np.zeros(0, dtype=int)
    with np.errstate(over="ignore", invalid="ignore"):
        jump = np.minimum(np.abs(np.diff(column, prepend=column[1])),
                          np.abs(np.diff(column[::-1], prepend=column[-2])[::-1]))
        far = (dev > ABSURD_FACTOR * scale) & (jump > ABSURD_FACTOR * diff_scale)
    return np.flatnonzero(far)


def repair_absurd(data: Array, names: Sequence[str], dt: float) -> tuple[Array, list[str]]:
    """Replace each absurd sample (:func:`absurd_samples`) by linear interpolation between its
    channel's nearest sound samples, and say so; refuse a channel with more than
    :func:`allowed_absurd` of them (the record is then broken, not glitched)."""
    data = data.copy()
    notes = []
    for j, name in enumerate(names):
        bad = absurd_samples(data[:, j])
        if not bad.size:
            continue
        listed = ", ".join(f"t = {k * dt:.6g} s: {data[k, j]:.6g}" for k in bad[:5])
        more = f" and {bad.size - 5} more" if bad.size > 5 else ""
        if bad.size > allowed_absurd(data.shape[0]):
            raise IdentificationError(
                f"channel {name}: {bad.size} samples no physical signal makes (more than "
                f"{ABSURD_FACTOR:.0e} robust scales from the rest: {listed}{more}); more than "
                f"{allowed_absurd(data.shape[0])} in {data.shape[0]}: the record is broken")
        good = np.setdiff1d(np.arange(data.shape[0]), bad)
        data[bad, j] = np.interp(bad, good, data[good, j])
        notes.append(f"channel {name}: replaced {bad.size} sample(s) no physical signal makes "
                     f"by linear interpolation ({listed}{more}; more than {ABSURD_FACTOR:.0e} "
                     "robust scales from the rest)")
    return data, notes


def allowed_absurd(samples: int) -> int:
    """The most absurd samples per channel that interpolation may replace: one in
    :data:`ABSURD_SHARE` (at least one). Each replaced sample is a guess of the state-space
    record the methods need; beyond that share the guesses would shape the model."""
    return max(1, samples // ABSURD_SHARE)


def check_length(samples: int, needed: int, order: int, names: Sequence[str], why: str) -> None:
    """Refuse a record of fewer than ``needed`` samples for ``order``."""
    if samples < needed:
        raise IdentificationError(
            f"channels {', '.join(names)}: {samples} samples too short for order {order} "
            f"({why} needs at least {needed})")


def _excitation_order_rank(u: Array, order: int) -> tuple[int, float]:
    """Rank of ``R_n`` (see module) and its smallest relative eigenvalue."""
    u = u / channel_scales(u)
    rows = u.shape[0] - order + 1
    phi = np.hstack([u[order - 1 - i: order - 1 - i + rows] for i in range(order)])
    eig = np.linalg.eigvalsh(phi.T @ phi / rows)
    top = max(float(eig[-1]), np.finfo(float).tiny)
    ratio = max(float(eig[0]), 0.0) / top
    return int(np.sum(eig > EXCITATION_TOLERANCE * top)), ratio


def check_excitation(u: Array, order: int, names: Sequence[str]) -> None:
    """Refuse inputs that are not persistently exciting of order ``order`` (module docstring)."""
    n_samples, r = u.shape
    if order < 1 or n_samples <= order * r:
        return  # the length check speaks for records this short
    for j, name in enumerate(names):
        rank, ratio = _excitation_order_rank(u[:, j: j + 1], order)
        if rank < order:
            raise IdentificationError(
                f"input {name} is not persistently exciting of order {order}: it excites "
                f"{rank} directions (smallest covariance eigenvalue {ratio:.2g} of the largest; "
                f"{rank // 2} sinusoids drive at most {rank // 2} modes); excite with broadband "
                f"noise or lower the order")
    if r > 1:
        rank, ratio = _excitation_order_rank(u, order)
        if rank < order * r:
            raise IdentificationError(
                f"inputs {', '.join(names)} are not jointly persistently exciting of order "
                f"{order} (rank {rank} of {order * r}): they are (nearly) copies of each other")
