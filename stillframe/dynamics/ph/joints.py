"""Connections between the blocks' ports: joints, clamps and supports (seed 000 §5.1–5.2).

Each connection is a position-level constraint g(q, t) = 0 between port positions
p = [x, y, φ]. The system imposes it at velocity level, (∂g/∂q) A ν + ∂g/∂t = 0, which is the
transformer interconnection of eq. 41: for a revolute joint between port C of body 1 and port P
of body 2, R(θ₁)y_C1 = R(θ₂)y_P2 (body-frame velocities), i.e. y_P2 = R(θ₂ − θ₁)ᵀ y_C1 with the
multiplier λ as the joint force. Keeping g itself lets the integrator remove the position drift
(:mod:`stillframe.dynamics.ph.integrator`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

Port = tuple[str, str]  # (body name, port name)
PortPosition = Callable[[np.ndarray, Port], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Link:
    """p_a[c] − p_b[c] = offset[c] for the components c (0: x, 1: y, 2: angle).

    components (0, 1): revolute joint (eq. 40–41); (0, 1, 2): clamp (rigid connection)."""

    a: Port
    b: Port
    components: tuple[int, ...]
    offset: tuple[float, ...] | None = None

    def residual(self, position: PortPosition, q: np.ndarray, t: float,
                 ) -> tuple[np.ndarray, np.ndarray]:
        pa, ja = position(q, self.a)
        pb, jb = position(q, self.b)
        c = list(self.components)
        offset = np.zeros(len(c)) if self.offset is None else np.asarray(self.offset)
        return pa[c] - pb[c] - offset, ja[c] - jb[c]

    def rate(self, t: float) -> np.ndarray:
        return np.zeros(len(self.components))


@dataclass(frozen=True)
class Support:
    """p[c] = path(t)[c]: a port held to ground (path constant: v_P = 0, ω = 0, v_C = 0 of §6.1),
    on a slide (one component), or driven along a prescribed path (the crank of §6.2: a flow
    input whose conjugate output is the multiplier)."""

    port: Port
    components: tuple[int, ...]
    path: Callable[[float], Sequence[float]]
    velocity: Callable[[float], Sequence[float]] | None = None

    def residual(self, position: PortPosition, q: np.ndarray, t: float,
                 ) -> tuple[np.ndarray, np.ndarray]:
        p, jac = position(q, self.port)
        c = list(self.components)
        return p[c] - np.asarray(self.path(t), dtype=float), jac[c]

    def rate(self, t: float) -> np.ndarray:
        """∂g/∂t = −path'(t)."""
        if self.velocity is None:
            return np.zeros(len(self.components))
        return -np.asarray(self.velocity(t), dtype=float)


def fixed(values: Sequence[float]) -> Callable[[float], Sequence[float]]:
    """A constant path."""
    frozen = tuple(float(v) for v in values)
    return lambda _t: frozen


Connection = Link | Support
