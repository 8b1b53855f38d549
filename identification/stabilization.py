"""Stabilization diagram data: the modes of the realizations of one Hankel factorization at a
range of orders (thesis §3.6: physical modes persist as the order grows, noise modes wander)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from identification.era import HankelFactorization
from identification.modal import modal_parameters

FREQUENCY_TOLERANCE = 0.01
"""A pole is stable when the previous order has one within this relative frequency ..."""
DAMPING_TOLERANCE = 0.05
"""... and within this relative damping ratio."""


@dataclass(frozen=True)
class OrderPoles:
    """The oscillatory poles (0 < ζ < 1) of the realization of one order."""

    order: int
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    stable: np.ndarray


def stabilization(factorization: HankelFactorization, dt: float, orders: Sequence[int]
                  ) -> list[OrderPoles]:
    """Poles per order, each flagged stable against the previous order's poles."""
    out: list[OrderPoles] = []
    prev_f = prev_z = np.empty(0)
    for n in orders:
        real = factorization.realize(n)
        modes = modal_parameters(real.A, real.C, dt)
        keep = (modes.damping_ratio > 0) & (modes.damping_ratio < 1)
        f, z = modes.frequency_hz[keep], modes.damping_ratio[keep]
        if prev_f.size:
            df = np.abs(f[:, None] - prev_f[None, :]) / f[:, None]
            dz = np.abs(z[:, None] - prev_z[None, :]) / z[:, None]
            stable = np.any((df < FREQUENCY_TOLERANCE) & (dz < DAMPING_TOLERANCE), axis=1)
        else:
            stable = np.zeros(f.size, dtype=bool)
        out.append(OrderPoles(n, f, z, stable))
        prev_f, prev_z = f, z
    return out


def diagram_orders(chosen: int, rank: int) -> list[int]:
    """Even orders from 2 up to twice the chosen order (at least 20), within the rank."""
    top = min(max(2 * chosen, 20), rank)
    return list(range(2, top + 1, 2))
