"""Linear structures that carry the pendulum: lumped floors, FE columns, Craig–Bampton reduction.

A :class:`Structure` is the frame without the pendulum: constant mass, damping and stiffness
matrices on its DOFs ``q_s``, with the three floor displacements at ``floor_index``. The three
models of the rig differ only in how this structure is built; the nonlinear pendulum on floor 3
(:mod:`stillframe.dynamics.models.frame`) is the same for all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from stillframe.config.scene import Rig
from stillframe.errors import InputError


@dataclass(frozen=True)
class DampingParts:
    """C = a M + b K + U diag(g) Uᵀ: a banded part plus a low-rank modal correction.

    Kept apart so that fast solvers can keep the banded structure of M and K (FE DOFs ordered
    by height) and handle the rank-r part by the Woodbury identity.
    """

    mass_coefficient: float
    stiffness_coefficient: float
    shapes: np.ndarray  # U, n × r
    gains: np.ndarray  # g, r

    def matrix(self, mass: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
        """The dense C = a M + b K + U diag(g) Uᵀ for the given mass and stiffness matrices."""
        low_rank = (self.shapes * self.gains) @ self.shapes.T
        return self.mass_coefficient * mass + self.stiffness_coefficient * stiffness + low_rank


@dataclass(frozen=True)
class Structure:
    """Constant structural matrices; ``floor_index[i]`` is floor i+1's DOF in ``q_s``."""

    name: str
    mass: np.ndarray
    stiffness: np.ndarray
    floor_index: tuple[int, int, int]
    dof_names: tuple[str, ...]
    damping: np.ndarray | None = None
    damping_parts: DampingParts | None = None  # the same C split into banded + low rank

    @property
    def n_dof(self) -> int:
        """The number of degrees of freedom (the size of M)."""
        return self.mass.shape[0]

    def with_damping(self, parts: DampingParts) -> Structure:
        """This structure with the damping C = ``parts.matrix(M, K)``, its parts kept."""
        return Structure(self.name, self.mass, self.stiffness, self.floor_index,
                         self.dof_names, parts.matrix(self.mass, self.stiffness), parts)


def bending_stiffness(rig: Rig) -> np.ndarray:
    """n E J of each story's blades (n of them), times the story's ``stiffness_factors``."""
    c = rig.columns
    inertia = c.width * c.thickness**3 / 12.0
    return c.per_story * c.youngs_modulus * inertia * np.asarray(c.stiffness_factors)


def story_stiffness(rig: Rig) -> np.ndarray:
    """k_i = n 12 E J / L_i^3 for n blades clamped in non-rotating floors (thesis eq. 5.41–5.43)."""
    return 12.0 * bending_stiffness(rig) / np.asarray(rig.columns.lengths) ** 3


def lumped_structure(rig: Rig) -> Structure:
    """Three rigid floors on massless springs (thesis eq. 5.48, floor masses of eq. 5.57)."""
    k1, k2, k3 = story_stiffness(rig)
    stiffness = np.array([[k1 + k2, -k2, 0.0], [-k2, k2 + k3, -k3], [0.0, -k3, k3]])
    return Structure("lumped", np.diag(rig.floor_masses), stiffness, (0, 1, 2), ("x1", "x2", "x3"))


def beam_element(length: float, ei: float, rho_a: float) -> tuple[np.ndarray, np.ndarray]:
    """Hermite bending element on (w1, θ1, w2, θ2): consistent mass and stiffness.

    The lateral-bending blocks of thesis eq. 5.108 (mass) and 5.112 (stiffness).
    """
    L = length
    k = ei / L**3 * np.array([
        [12.0, 6 * L, -12.0, 6 * L],
        [6 * L, 4 * L**2, -6 * L, 2 * L**2],
        [-12.0, -6 * L, 12.0, -6 * L],
        [6 * L, 2 * L**2, -6 * L, 4 * L**2],
    ])
    m = rho_a * L / 420.0 * np.array([
        [156.0, 22 * L, 54.0, -13 * L],
        [22 * L, 4 * L**2, 13 * L, -3 * L**2],
        [54.0, 13 * L, 156.0, -22 * L],
        [-13 * L, -3 * L**2, -22 * L, 4 * L**2],
    ])
    return m, k


def _scatter_add(target: np.ndarray, local: np.ndarray, dofs: list[int]) -> None:
    """Add ``local`` into ``target`` at ``dofs``; entries at DOF −1 (held at zero) are dropped."""
    index = np.asarray(dofs)
    keep = index >= 0
    target[np.ix_(index[keep], index[keep])] += local[np.ix_(keep, keep)]


def column_matrices(length: float, n_elements: int, ei: float,
                    rho_a: float) -> tuple[np.ndarray, np.ndarray]:
    """Mass and stiffness of one story's column clamped at both ends against rotation.

    DOFs: bottom deflection, the inner nodes' (w, θ) from the bottom up, top deflection. The end
    rotations are held at zero (the floors do not rotate).
    """
    n_inner = 2 * (n_elements - 1)
    n = n_inner + 2
    top = n - 1
    mass = np.zeros((n, n))
    stiffness = np.zeros((n, n))
    m_el, k_el = beam_element(length / n_elements, ei, rho_a)
    for e in range(n_elements):
        # local (w1, θ1, w2, θ2) → column DOF, or -1 where the end rotation is held
        lower = (0, -1) if e == 0 else (2 * e - 1, 2 * e)
        upper = (top, -1) if e == n_elements - 1 else (2 * e + 1, 2 * e + 2)
        _scatter_add(mass, m_el, [*lower, *upper])
        _scatter_add(stiffness, k_el, [*lower, *upper])
    return mass, stiffness


def fe_structure(rig: Rig, elements_per_column: int) -> Structure:
    """Euler–Bernoulli columns, ``elements_per_column`` elements per story (thesis §5.4).

    Assumptions: the ``per_story`` blades of a story bend alike and are lumped into one beam of
    n-fold EJ (times the story's ``stiffness_factors``) and ρA; columns are inextensible; their
    ends are clamped in rigid floors that do not rotate, so end rotations are zero and end
    deflections are the floor displacements.
    DOFs: x1, x2, x3, then each story's inner nodes (w, θ) from the ground up.
    """
    n_e = elements_per_column
    c = rig.columns
    ei = bending_stiffness(rig)
    rho_a = c.per_story * c.density * c.width * c.thickness
    n_inner = 2 * (n_e - 1)
    n = 3 + 3 * n_inner
    mass = np.zeros((n, n))
    stiffness = np.zeros((n, n))
    names = ["x1", "x2", "x3"]
    for story, length in enumerate(c.lengths):
        names += [f"s{story + 1}n{j}{dof}" for j in range(1, n_e) for dof in ("w", "th")]
        m_col, k_col = column_matrices(length, n_e, float(ei[story]), rho_a)
        inner = list(range(3 + story * n_inner, 3 + (story + 1) * n_inner))
        dofs = [story - 1, *inner, story]  # the ground (-1) is dropped
        _scatter_add(mass, m_col, dofs)
        _scatter_add(stiffness, k_col, dofs)
    mass[:3, :3] += np.diag(rig.floor_masses)
    return Structure(f"fe{n_e}", mass, stiffness, (0, 1, 2), tuple(names))


def craig_bampton(full: Structure, modes: int) -> Structure:
    """Craig–Bampton reduction with the floor DOFs as boundary and ``modes`` fixed-interface modes.

    T = [[I, 0], [Ψ, Φ]], Ψ = -K_ii⁻¹ K_ib (constraint modes), Φ the lowest fixed-interface
    modes of (K_ii, M_ii). Floor DOFs stay physical, so loads and the pendulum act on them as in
    the full model. With all inner modes kept it spans the full space.
    """
    b = np.asarray(full.floor_index)
    inner = np.setdiff1d(np.arange(full.n_dof), b)
    if modes > inner.size:
        raise InputError(
            f"model.modes: {modes} retained modes but the FE structure has only {inner.size} "
            "inner DOFs (raise model.elements_per_column or lower model.modes)"
        )
    K, M = full.stiffness, full.mass
    kii, kib = K[np.ix_(inner, inner)], K[np.ix_(inner, b)]
    psi = -sla.solve(kii, kib, assume_a="pos")
    _, phi = sla.eigh(kii, M[np.ix_(inner, inner)], subset_by_index=(0, modes - 1))
    T = np.zeros((full.n_dof, 3 + modes))
    T[b, :3] = np.eye(3)
    T[np.ix_(inner, np.arange(3))] = psi
    T[np.ix_(inner, np.arange(3, 3 + modes))] = phi
    names = ("x1", "x2", "x3", *(f"eta{j + 1}" for j in range(modes)))
    return Structure(f"modal{modes}", T.T @ M @ T, T.T @ K @ T, (0, 1, 2), names)
