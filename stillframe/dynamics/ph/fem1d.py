"""One-dimensional finite-element spaces of the pH beam (seed 000 §4.3, journal version).

P1 for the axial velocity, cubic Hermite for the transverse velocity, DG0 for the axial stress
and DG1 for the bending moment, on a uniform mesh of [0, L]. Every basis is tabulated at the
mesh's Gauss points, so the beam's matrices are weighted sums over those points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stillframe.errors import InputError

GAUSS_POINTS = 5  # per element: exact for the degree-7 products of the beam's integrands

CONDITIONS = ("cantilever", "simply_supported")


@dataclass(frozen=True)
class BeamMesh:
    """Uniform mesh of [0, length]; the Dirichlet ``condition`` of seed 000 §4.3 removes DOFs."""

    length: float
    elements: int
    condition: str

    def __post_init__(self) -> None:
        if self.elements < 1:
            raise InputError(f"beam elements must be >= 1, got {self.elements}")
        if self.condition not in CONDITIONS:
            raise InputError(f"beam condition must be one of {CONDITIONS}, got {self.condition!r}")

    @property
    def h(self) -> float:
        """The element length [m]."""
        return self.length / self.elements

    def axial_dofs(self) -> np.ndarray:
        """Free P1 nodes: u_x(0) = 0 in both conditions."""
        return np.arange(1, self.elements + 1)

    def transverse_dofs(self) -> np.ndarray:
        """Free Hermite DOFs (w_i at 2i, θ_i at 2i+1): cantilever w_0 = θ_0 = 0; simply
        supported w_0 = w_N = 0."""
        all_dofs = np.arange(2 * (self.elements + 1))
        held = {0, 1} if self.condition == "cantilever" else {0, 2 * self.elements}
        return np.array([d for d in all_dofs if d not in held])

    def quadrature(self) -> tuple[np.ndarray, np.ndarray]:
        """Global Gauss points and weights."""
        xi, wi = np.polynomial.legendre.leggauss(GAUSS_POINTS)
        left = np.arange(self.elements)[:, None] * self.h
        x = (left + 0.5 * self.h * (xi + 1.0)).ravel()
        w = np.tile(0.5 * self.h * wi, self.elements)
        return x, w

    def _locate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.atleast_1d(np.asarray(x, dtype=float))
        element = np.clip(np.floor(x / self.h).astype(int), 0, self.elements - 1)
        return element, (x - element * self.h) / self.h

    def p1(self, x: np.ndarray, derivative: int = 0) -> np.ndarray:
        """Free P1 basis (or its derivative) at points x: shape (len(x), n_axial)."""
        element, s = self._locate(x)
        full = np.zeros((s.size, self.elements + 1))
        rows = np.arange(s.size)
        if derivative == 0:
            full[rows, element], full[rows, element + 1] = 1.0 - s, s
        else:
            full[rows, element], full[rows, element + 1] = -1.0 / self.h, 1.0 / self.h
        return full[:, self.axial_dofs()]

    def hermite(self, x: np.ndarray, derivative: int = 0) -> np.ndarray:
        """Free cubic Hermite basis (or its 1st/2nd derivative) at x: (len(x), n_transverse)."""
        element, s = self._locate(x)
        h = self.h
        if derivative == 0:
            shapes = [1 - 3 * s**2 + 2 * s**3, h * (s - 2 * s**2 + s**3),
                      3 * s**2 - 2 * s**3, h * (-(s**2) + s**3)]
        elif derivative == 1:
            shapes = [(-6 * s + 6 * s**2) / h, 1 - 4 * s + 3 * s**2,
                      (6 * s - 6 * s**2) / h, -2 * s + 3 * s**2]
        else:
            shapes = [(-6 + 12 * s) / h**2, (-4 + 6 * s) / h,
                      (6 - 12 * s) / h**2, (-2 + 6 * s) / h]
        full = np.zeros((s.size, 2 * (self.elements + 1)))
        rows = np.arange(s.size)
        for k, shape in enumerate(shapes):
            full[rows, 2 * element + k] += shape
        return full[:, self.transverse_dofs()]

    def dg0(self, x: np.ndarray) -> np.ndarray:
        """Piecewise-constant basis at x: (len(x), elements)."""
        element, _ = self._locate(x)
        full = np.zeros((element.size, self.elements))
        full[np.arange(element.size), element] = 1.0
        return full

    def dg1(self, x: np.ndarray) -> np.ndarray:
        """Discontinuous piecewise-linear basis (element end values) at x: (len(x), 2·elements)."""
        element, s = self._locate(x)
        full = np.zeros((s.size, 2 * self.elements))
        rows = np.arange(s.size)
        full[rows, 2 * element], full[rows, 2 * element + 1] = 1.0 - s, s
        return full
