"""Classical displacement-based FE of planar frames: the independent reference for the pH models.

Each element is a bar (linear axial shape) plus a Hermite bending element
(:func:`stillframe.dynamics.models.structure.beam_element`) on nodal DOFs (u_x, u_y, θ) in the
inertial frame, rotated to the element's direction. Revolute joints share the translations of two
nodes, supports remove DOFs, lumped masses add to translations. Nothing here uses the pH code.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from stillframe.dynamics.models.structure import beam_element


def frame_element(length: float, angle: float, rho_a: float, ea: float, ei: float,
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Consistent mass and stiffness (6×6, inertial DOFs u1, v1, θ1, u2, v2, θ2)."""
    mb, kb = beam_element(length, ei, rho_a)
    m, k = np.zeros((6, 6)), np.zeros((6, 6))
    ax, tr = [0, 3], [1, 2, 4, 5]
    k[np.ix_(ax, ax)] = ea / length * np.array([[1.0, -1.0], [-1.0, 1.0]])
    m[np.ix_(ax, ax)] = rho_a * length / 6.0 * np.array([[2.0, 1.0], [1.0, 2.0]])
    k[np.ix_(tr, tr)] = kb
    m[np.ix_(tr, tr)] = mb
    c, s = np.cos(angle), np.sin(angle)
    r = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    T = sla.block_diag(r, r)
    return T.T @ m @ T, T.T @ k @ T


@dataclass
class FrameModel:
    """DOF bookkeeping: every node has (u_x, u_y, θ) indices; joints alias translations."""

    dofs: list[list[int]] = field(default_factory=list)
    count: int = 0
    elements: list[tuple[int, int, float, float, float, float, float]] = field(
        default_factory=list)
    masses: list[tuple[int, float]] = field(default_factory=list)
    fixed: set[int] = field(default_factory=set)

    def node(self, translation_of: int | None = None) -> int:
        """A new node; ``translation_of`` pins it to an existing node (revolute joint)."""
        if translation_of is None:
            idx = [self.count, self.count + 1, self.count + 2]
            self.count += 3
        else:
            idx = [*self.dofs[translation_of][:2], self.count]
            self.count += 1
        self.dofs.append(idx)
        return len(self.dofs) - 1

    def link(self, start: int, length: float, angle: float, elements: int, rho_a: float,
             ea: float, ei: float) -> int:
        """A straight beam from node ``start``; returns its end node."""
        node = start
        for _ in range(elements):
            nxt = self.node()
            self.elements.append((node, nxt, length / elements, angle, rho_a, ea, ei))
            node = nxt
        return node

    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        M, K = np.zeros((self.count, self.count)), np.zeros((self.count, self.count))
        for a, b, length, angle, rho_a, ea, ei in self.elements:
            m, k = frame_element(length, angle, rho_a, ea, ei)
            idx = self.dofs[a] + self.dofs[b]
            M[np.ix_(idx, idx)] += m
            K[np.ix_(idx, idx)] += k
        for node, mass in self.masses:
            for d in self.dofs[node][:2]:
                M[d, d] += mass
        free = np.array([d for d in range(self.count) if d not in self.fixed])
        return M, K, free

    def pulsations(self, count: int) -> np.ndarray:
        M, K, free = self.matrices()
        w2 = sla.eigh(K[np.ix_(free, free)], M[np.ix_(free, free)], eigvals_only=True)
        return np.sqrt(np.clip(w2[:count], 0.0, None))


def fix(model: FrameModel, node: int, components: Sequence[int]) -> None:
    model.fixed.update(model.dofs[node][c] for c in components)
