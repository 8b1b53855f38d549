"""Modal parameters of a discrete state-space model (thesis §3.3, eqs. 3.49, 3.56–3.58, 3.204–3.207)
and the modal assurance criterion (MAC).

Mode shapes are the columns of ``C Psi`` (eq. 3.207): complex, at the sensors. Only one
eigenvalue of each complex-conjugate pair is kept (the one with positive imaginary part; real
eigenvalues once).
Modes are sorted by natural frequency. Each shape is normalised so that its reference component
is 1 + 0j: by default the component of largest magnitude, or a given reference sensor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import InputError

__all__ = ["ModalTable", "continuous_eigenvalues", "mac", "modal_parameters"]

Array = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True)
class ModalTable:
    """Natural frequencies (Hz), damping ratios, continuous eigenvalues, shapes ``(m, modes)``."""

    frequency_hz: Array
    damping_ratio: Array
    eigenvalues: ComplexArray
    shapes: ComplexArray

    def __len__(self) -> int:
        return int(self.frequency_hz.size)

    @property
    def omega(self) -> Array:
        """Natural circular frequencies (rad/s)."""
        return 2.0 * np.pi * self.frequency_hz

    def magnitude_phase(self, mode: int) -> list[list[float]]:
        """``[[magnitude, phase_rad], ...]`` of one shape, per sensor."""
        shape = self.shapes[:, mode]
        return [[float(abs(c)), float(np.angle(c))] for c in shape]


def continuous_eigenvalues(discrete: ComplexArray, dt: float) -> ComplexArray:
    """``lambda_c = ln(lambda) / dt`` (eq. 3.58), principal branch (|Im| <= pi / dt)."""
    discrete = np.asarray(discrete, dtype=complex)
    if np.any(discrete == 0):
        raise InputError("a discrete eigenvalue is zero: the model has no continuous equivalent")
    return np.log(discrete) / dt


def modal_parameters(A: Array, C: Array, dt: float, reference: int | None = None) -> ModalTable:
    """Frequencies, damping ratios and normalised shapes of ``(A, C)`` sampled at ``dt``."""
    if dt <= 0 or not np.isfinite(dt):
        raise InputError(f"sampling interval must be positive, got {dt}")
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(C))):
        raise InputError("state-space matrices contain NaN or inf")
    if reference is not None and not 0 <= reference < C.shape[0]:
        raise InputError(f"reference sensor {reference} is outside 0..{C.shape[0] - 1}")
    lam, psi = np.linalg.eig(A)
    keep = lam.imag >= 0
    lam_c = continuous_eigenvalues(lam[keep], dt)
    shapes = C @ psi[:, keep]
    wn = np.abs(lam_c)
    zeta = np.where(wn > 0, -lam_c.real / np.where(wn > 0, wn, 1.0), 1.0)
    order = np.argsort(wn, kind="stable")
    shapes = shapes[:, order]
    for j in range(shapes.shape[1]):
        ref = int(np.argmax(np.abs(shapes[:, j]))) if reference is None else reference
        if shapes[ref, j] != 0:
            shapes[:, j] = shapes[:, j] / shapes[ref, j]
    return ModalTable(
        frequency_hz=wn[order] / (2.0 * np.pi),
        damping_ratio=zeta[order],
        eigenvalues=lam_c[order],
        shapes=shapes,
    )


def mac(shapes_a: ComplexArray, shapes_b: ComplexArray) -> Array:
    """MAC matrix ``|a_i^H b_j|^2 / ((a_i^H a_i)(b_j^H b_j))`` between the columns of two shape
    sets measured at the same sensors (pass the same set twice for the auto-MAC)."""
    a = np.asarray(shapes_a, dtype=complex)
    b = np.asarray(shapes_b, dtype=complex)
    if a.ndim != 2 or b.ndim != 2 or a.shape[0] != b.shape[0]:
        raise InputError(f"shape sets must share their sensor count, got {a.shape} and {b.shape}")
    cross = np.abs(a.conj().T @ b) ** 2
    norm_a = np.sum(np.abs(a) ** 2, axis=0)
    norm_b = np.sum(np.abs(b) ** 2, axis=0)
    return cross / np.outer(norm_a, norm_b)
