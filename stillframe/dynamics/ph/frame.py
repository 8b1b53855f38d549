"""The thesis's three-story frame with its pendulum as a pHDAE (``model.type: ph``).

Blocks: each story's blades are one floating beam (n-fold ρA, EA and EI, the FE model's lumping,
thesis §5.4), vertical, cantilevered in its own frame; the floors are rigid bodies; the pendulum
is a rigid body (mass m4, centre of mass at L4, inertia I_zz,4 about it) with gravity (Remark 1).
Connections (transformer interconnections, eq. 41): column bottoms clamped into the ground or the
floor below, column tops clamped into the floor above, floors held to horizontal motion without
rotation (the FE model's assumptions), the pendulum on a revolute joint at floor 3 with the
hinge damping r4 as a rotary damper. Input ports u = [f1, f2, f3, torque]: horizontal forces on
the floors and the hinge torque (whose reaction on the non-rotating floor does no work).
Unlike the FE model the columns are extensible (axial P1/DG0 fields); their axial modes sit in
the kHz range and leave the first frequencies unchanged to the digits the tests check.
"""

from __future__ import annotations

import numpy as np

from stillframe.config.scene import Rig
from stillframe.dynamics.models.structure import bending_stiffness
from stillframe.dynamics.ph.body import BeamSection, floating_beam, rigid_body
from stillframe.dynamics.ph.joints import Link, Support, fixed
from stillframe.dynamics.ph.system import BodyDamping, PHSystem, PortInput, RotaryDamper
from stillframe.errors import InputError

UP = np.pi / 2
FLOOR_INERTIA = 1.0  # kg m²; the floors do not rotate, so this value never enters the motion


def column_section(rig: Rig, story: int) -> BeamSection:
    """The lumped blades of ``story`` (0-based): n-fold ρA and EA, and EJ times the story's
    ``stiffness_factors``."""
    c = rig.columns
    area = c.per_story * c.width * c.thickness
    return BeamSection(c.density * area, c.youngs_modulus * area,
                       float(bending_stiffness(rig)[story]))


def floor_heights(rig: Rig) -> np.ndarray:
    return np.cumsum(rig.columns.lengths)


def frame_system(rig: Rig, elements: int, rayleigh: tuple[float, float] | None = None,
                 ) -> PHSystem:
    """The frame as blocks and connections; ``rayleigh`` = (α, β) adds R = αM + βDᵀC⁻¹D per
    column and αm per floor (both ≥ 0: R ⪰ 0)."""
    if rayleigh is not None and min(rayleigh) < 0:
        raise InputError(f"model.type ph: Rayleigh damping needs alpha, beta >= 0 (R ⪰ 0), "
                         f"got {rayleigh}")
    heights = floor_heights(rig)
    p = rig.pendulum
    bodies, connections, dampers = [], [], []
    below = None
    for story, (length, height, mass) in enumerate(zip(rig.columns.lengths, heights,
                                                       rig.floor_masses, strict=True)):
        column = floating_beam(f"column{story + 1}", length, column_section(rig, story),
                               elements, "cantilever")
        floor = rigid_body(f"floor{story + 1}", mass, FLOOR_INERTIA, 0.0, {"P": 0.0})
        bodies += [column, floor]
        bottom = (column.name, "P")
        if below is None:
            connections.append(Support(bottom, (0, 1, 2), fixed([0.0, 0.0, UP])))
        else:
            connections.append(Link(below, bottom, (0, 1, 2), (0.0, 0.0, -UP)))
        connections.append(Link((floor.name, "P"), (column.name, "C"), (0, 1, 2),
                                (0.0, 0.0, -UP)))
        connections.append(Support((floor.name, "P"), (1, 2), fixed([height, 0.0])))
        if rayleigh is not None:
            alpha, beta = rayleigh
            D, C = column.stress_coupling(), column.compliance()
            dampers.append(BodyDamping(column.name, alpha * column.mass_matrix()
                                       + beta * D.T @ np.linalg.solve(C, D)))
            dampers.append(BodyDamping(floor.name, alpha * floor.mass_matrix()))
        below = (floor.name, "P")
    pendulum = rigid_body("pendulum", p.mass, p.inertia, p.half_length, {"P": 0.0},
                          gravity=rig.gravity)
    bodies.append(pendulum)
    connections.append(Link(("floor3", "P"), ("pendulum", "P"), (0, 1)))
    dampers.append(RotaryDamper(("pendulum", "P"), ("floor3", "P"), p.hinge_damping))
    inputs = [PortInput(f"f{i}", (f"floor{i}", "P"), (1.0, 0.0, 0.0)) for i in (1, 2, 3)]
    inputs.append(PortInput("torque", ("pendulum", "P"), (0.0, 0.0, 1.0)))
    return PHSystem(bodies, connections, inputs, dampers, name=f"ph{elements}")


def rest_configuration(system: PHSystem, rig: Rig, floors: np.ndarray | None = None,
                       phi: float = 0.0) -> np.ndarray:
    """q with the floors displaced by ``floors``, the pendulum at φ (θ = φ − π/2) and the column
    deflections in static equilibrium (the stresses follow from :func:`static_stresses`)."""
    floors = np.zeros(3) if floors is None else np.asarray(floors, dtype=float)
    heights = floor_heights(rig)
    q = np.zeros(system.n_q)
    base = np.zeros(2)
    for story in range(3):
        top = np.array([floors[story], heights[story]])
        column = system.q_slices[f"column{story + 1}"]
        q[column][:3] = [*base, UP]
        q[system.q_slices[f"floor{story + 1}"]][:2] = top
        base = top
    q[system.q_slices["pendulum"]][:3] = [floors[2], heights[2], phi - UP]
    if np.any(floors):
        q = _static_deflection(system, q)
    return system.assemble(q)


def _static_deflection(system: PHSystem, q: np.ndarray) -> np.ndarray:
    """Column deformation DOFs minimising the elastic energy at the given floor positions."""
    D, C = system.stress_coupling, system.compliance
    K = D.T @ np.linalg.solve(C, D)
    flex = np.flatnonzero(np.any(K != 0, axis=0))
    g, Dg, _ = system.constraints(q, 0.0)
    # minimise ½ dqᵀ K dq on the flexible DOFs subject to the linearised connections
    k = Dg.shape[0]
    n = flex.size
    kkt = np.block([[K[np.ix_(flex, flex)], Dg[:, flex].T], [Dg[:, flex], np.zeros((k, k))]])
    rhs = np.concatenate([np.zeros(n), -g])
    dq = np.linalg.lstsq(kkt, rhs, rcond=None)[0][:n]
    out = q.copy()
    out[flex] += dq
    return out


def static_stresses(system: PHSystem, q: np.ndarray) -> np.ndarray:
    """σ = C⁻¹ D u: the stresses of the deformation in q (Hooke's law of the mixed elements)."""
    D, C = system.stress_coupling, system.compliance
    return np.linalg.solve(C, D @ q)


def sensors(system: PHSystem, e: np.ndarray) -> dict[str, np.ndarray]:
    """Floor displacements and velocities (inertial x) and φ, φ̇."""
    q, nu, _ = system.split(e)
    floors = np.array([q[system.q_slices[f"floor{i}"]][0] for i in (1, 2, 3)])
    A = system.kinematics(q)
    rates = A @ nu
    velocities = np.array([rates[system.q_slices[f"floor{i}"]][0] for i in (1, 2, 3)])
    pend = system.q_slices["pendulum"]
    return {"floors": floors, "floor_velocities": velocities,
            "phi": float(q[pend][2] + UP), "phi_rate": float(rates[pend][2])}
