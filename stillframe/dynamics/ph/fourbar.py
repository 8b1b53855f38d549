"""§6.1 of seed 000: linear analysis of the four-bar mechanism (Table 1, Fig. 5–6).

Crank, coupler and follower are floating beams, each cantilevered in its own frame; lumped masses
of 0.042 kg at P of coupler and follower (eq. 48); revolute joints between the links (eq. 41);
ground constraints v_P1 = 0, ω_P1 = 0, v_C3 = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stillframe.dynamics.ph.body import BeamSection, floating_beam
from stillframe.dynamics.ph.classical_fe import FrameModel, fix
from stillframe.dynamics.ph.joints import Link, Support, fixed
from stillframe.dynamics.ph.linear import natural_frequencies
from stillframe.dynamics.ph.system import PHSystem
from stillframe.errors import InputError

DENSITY = 2714.0
YOUNG = 7.1e10
GROUND = 0.254
LENGTHS = (0.108, 0.2794, 0.2705)
AREAS = (1.0774e-4, 4.0645e-5, 4.0645e-5)
FLEXURAL = (11.472, 0.616, 0.616)
LUMPED = 0.042


@dataclass(frozen=True)
class Configuration:
    """Absolute link angles and joint positions for a crank angle θ₁."""

    angles: tuple[float, float, float]
    points: tuple[np.ndarray, np.ndarray, np.ndarray]  # crank pivot, crank tip, coupler tip


def configuration(crank_angle: float) -> Configuration:
    """Solve the loop closure L₁e(θ₁) + L₂e(θ₁+θ₂) + L₃e(θ₁+θ₂+θ₃) = (L₀, 0), the coupler–follower
    joint above the ground line (the open assembly of Fig. 5)."""
    l1, l2, l3 = LENGTHS
    a = np.zeros(2)
    b = l1 * np.array([np.cos(crank_angle), np.sin(crank_angle)])
    c = np.array([GROUND, 0.0])
    d = np.linalg.norm(c - b)
    if d > l2 + l3 or d < abs(l2 - l3):
        raise InputError(f"four-bar: no assembly at crank angle {np.degrees(crank_angle):g} deg")
    along = (l2**2 - l3**2 + d**2) / (2 * d)
    height = np.sqrt(max(l2**2 - along**2, 0.0))
    unit = (c - b) / d
    normal = np.array([-unit[1], unit[0]])
    joint = b + along * unit + height * normal
    if joint[1] < 0:
        joint = b + along * unit - height * normal
    angle2 = np.arctan2(*(joint - b)[::-1])
    angle3 = np.arctan2(*(c - joint)[::-1])
    return Configuration((crank_angle, angle2, angle3), (a, b, joint))


def sections() -> list[BeamSection]:
    return [BeamSection(DENSITY * a, YOUNG * a, ei) for a, ei in zip(AREAS, FLEXURAL, strict=True)]


def ph_system(crank_angle: float, elements: int) -> tuple[PHSystem, np.ndarray]:
    """The block diagram of Fig. 5 (right) and the assembled configuration q."""
    conf = configuration(crank_angle)
    names = ("crank", "coupler", "follower")
    bodies = [floating_beam(n, length, sec, elements, "cantilever",
                            lumped_mass=0.0 if n == "crank" else LUMPED)
              for n, length, sec in zip(names, LENGTHS, sections(), strict=True)]
    follower_end = conf.points[2] + LENGTHS[2] * np.array(
        [np.cos(conf.angles[2]), np.sin(conf.angles[2])])
    connections = [
        Support(("crank", "P"), (0, 1, 2), fixed([0.0, 0.0, crank_angle])),
        Link(("crank", "C"), ("coupler", "P"), (0, 1)),
        Link(("coupler", "C"), ("follower", "P"), (0, 1)),
        Support(("follower", "C"), (0, 1), fixed(follower_end)),
    ]
    system = PHSystem(bodies, connections)
    q = np.zeros(system.n_q)
    for body, point, angle in zip(names, conf.points, conf.angles, strict=True):
        sl = system.q_slices[body]
        q[sl][:3] = [*point, angle]
    return system, q


def ph_pulsations(crank_angle: float, elements: int, count: int = 3) -> np.ndarray:
    system, q = ph_system(crank_angle, elements)
    return natural_frequencies(system, q, count)[0]


def classical_pulsations(crank_angle: float, elements: int, count: int = 3) -> np.ndarray:
    """The same linked beams as a classical FE frame
    (:mod:`stillframe.dynamics.ph.classical_fe`)."""
    conf = configuration(crank_angle)
    model = FrameModel()
    pivot = model.node()
    fix(model, pivot, (0, 1, 2))
    end = pivot
    for k, (length, angle, sec) in enumerate(zip(LENGTHS, conf.angles, sections(),
                                                 strict=True)):
        start = end if k == 0 else model.node(translation_of=end)
        if k > 0:
            model.masses.append((start, LUMPED))
        end = model.link(start, length, angle, elements, sec.rho_a, sec.ea, sec.ei)
    fix(model, end, (0, 1))
    return model.pulsations(count)
