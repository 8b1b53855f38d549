"""Stabilization diagram: the modes of the realizations of increasing order from one Hankel
factorization (thesis §3.6; the usual way to read the order off ERA results).

A mode at order n is *stable* when a mode of order ``n - step`` lies within ``frequency_tol``
(relative) in frequency, within ``damping_tol`` (relative) in damping ratio and, when both have
shapes, has a MAC of at least ``mac_min`` with it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import InputError
from stillframe.identification.era import HankelFactorization
from stillframe.identification.modal import ModalTable, mac, modal_parameters

Array = NDArray[np.float64]


@dataclass(frozen=True)
class StabilizationRow:
    """Modes of one order with their stability flags."""

    order: int
    modes: ModalTable
    stable_frequency: NDArray[np.bool_]
    stable: NDArray[np.bool_]
    """Frequency, damping and MAC all within tolerance of the previous order."""


def stabilization_diagram(
    factorization: HankelFactorization,
    dt: float,
    orders: Sequence[int],
    frequency_tol: float = 0.01,
    damping_tol: float = 0.05,
    mac_min: float = 0.98,
) -> list[StabilizationRow]:
    """One :class:`StabilizationRow` per order (ascending); orders above the Hankel matrix's
    numerical rank are refused."""
    orders = sorted(set(int(n) for n in orders))
    if not orders or orders[0] < 1 or orders[-1] > factorization.numerical_rank:
        raise InputError(f"stabilization orders must lie in 1..{factorization.numerical_rank}")
    rows: list[StabilizationRow] = []
    previous: ModalTable | None = None
    for n in orders:
        real = factorization.realize(n)
        modes = modal_parameters(real.A, real.C, dt)
        stable_f = np.zeros(len(modes), dtype=bool)
        stable = np.zeros(len(modes), dtype=bool)
        if previous is not None and len(previous):
            stable_f, stable = matching_modes(modes, previous, frequency_tol, damping_tol,
                                              mac_min)
        rows.append(StabilizationRow(order=n, modes=modes, stable_frequency=stable_f,
                                     stable=stable))
        previous = modes
    return rows


def matching_modes(modes: ModalTable, other: ModalTable, frequency_tol: float,
                   damping_tol: float, mac_min: float,
                   ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """For each mode of ``modes``: whether ``other`` has one within ``frequency_tol`` in
    frequency, and whether it has one within all three tolerances (frequency, damping, MAC)."""
    if not len(modes) or not len(other):
        none = np.zeros(len(modes), dtype=bool)
        return none, none.copy()
    f, f0 = modes.frequency_hz[:, None], other.frequency_hz[None, :]
    z, z0 = modes.damping_ratio[:, None], other.damping_ratio[None, :]
    close_f = np.abs(f - f0) <= frequency_tol * np.abs(f0)
    close_z = np.abs(z - z0) <= damping_tol * np.abs(z0)
    close = close_f & close_z & (mac(modes.shapes, other.shapes) >= mac_min)
    return close_f.any(axis=1), close.any(axis=1)
