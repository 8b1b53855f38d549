"""§6.2 of seed 000: the rotating crank-slider (Fig. 7–8).

A rigid crank (0.15 m) turns at a constant 150 rad/s (``crank_rate``): its tip drives port P of
the flexible coupler (a prescribed-motion support, the flow input u_cl of eq. 49, its multiplier
the crank force). The coupler is a floating beam with the simply supported deformation
condition; a slider block (a rigid body) is pinned to its end C and slides on the ground line
y = 0. The coupler starts undeformed with the rigid velocities of the mechanism.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from stillframe.dynamics.ph.body import BeamSection, floating_beam, rigid_body
from stillframe.dynamics.ph.integrator import MidpointDAE, StepRecord, balance_error
from stillframe.dynamics.ph.joints import Link, Support, fixed
from stillframe.dynamics.ph.system import PHSystem
from stillframe.errors import InputError

CRANK = 0.15
COUPLER = 0.3


@dataclass(frozen=True)
class CrankSliderData:
    """Coupler section and slider mass: the paper's 6 mm steel rod (default) or the IVP test
    set's 8 mm square rod (:data:`TEST_SET`)."""

    area: float = np.pi * 0.003**2
    second_moment: float = np.pi * 0.006**4 / 64
    density: float = 7870.0
    young: float = 2e11
    slider_mass: float = 0.033
    crank_rate: float = 150.0


TEST_SET = CrankSliderData(area=0.008**2, second_moment=0.008**4 / 12, slider_mass=0.075552)
# Simeon's slider crank (Test Set for IVP Solvers), reference values at t = 0.1 s
TEST_SET_REFERENCE = {"coupler_angle": -0.3311734988256260, "slider_x": 0.1697373328427860,
                      "midpoint_deflection": 1.893192899613509e-4}


@dataclass(frozen=True)
class CrankSliderRun:
    times: np.ndarray
    crank_angle: np.ndarray
    w_mid_over_l: np.ndarray
    u_mid_over_l: np.ndarray
    coupler_angle: np.ndarray
    slider_x: np.ndarray
    energy_balance_error: float
    max_constraint_drift: float
    record: StepRecord


def system(elements: int, data: CrankSliderData = CrankSliderData()) -> PHSystem:
    """The block diagram of Fig. 7 (right)."""
    section = BeamSection(data.density * data.area, data.young * data.area,
                          data.young * data.second_moment)
    coupler = floating_beam("coupler", COUPLER, section, elements, "simply_supported")
    slider = rigid_body("slider", data.slider_mass, 1e-6, 0.0, {"P": 0.0})
    rate = data.crank_rate

    def crank_path(t: float) -> tuple[float, float]:
        return CRANK * np.cos(rate * t), CRANK * np.sin(rate * t)

    def crank_velocity(t: float) -> tuple[float, float]:
        return -CRANK * rate * np.sin(rate * t), CRANK * rate * np.cos(rate * t)

    connections = [
        Support(("coupler", "P"), (0, 1), crank_path, crank_velocity),
        Link(("coupler", "C"), ("slider", "P"), (0, 1)),
        Support(("slider", "P"), (1, 2), fixed([0.0, 0.0])),
    ]
    return PHSystem([coupler, slider], connections)


def initial_state(ph: PHSystem, data: CrankSliderData = CrankSliderData()) -> np.ndarray:
    """Crank angle 0, undeformed coupler along x, rigid velocities of the mechanism."""
    q = np.zeros(ph.n_q)
    q[ph.q_slices["coupler"]][:3] = [CRANK, 0.0, 0.0]
    q[ph.q_slices["slider"]][:3] = [CRANK + COUPLER, 0.0, 0.0]
    q = ph.assemble(q)
    guess = np.zeros(ph.n_q)
    cs = ph.q_slices["coupler"]
    guess[cs][1] = CRANK * data.crank_rate            # v_P^y in the coupler frame
    guess[cs][2] = -CRANK * data.crank_rate / COUPLER  # ω keeping C on the slide
    return ph.state(q, ph.consistent_velocity(q, guess))


def simulate(elements: int, t_end: float, dt: float, data: CrankSliderData = CrankSliderData(),
             progress: Callable[[float], None] | None = None, samples: int = 400,
             ) -> CrankSliderRun:
    """Integrate with the AVF midpoint rule; midpoint deformation at ``samples`` instants."""
    if elements < 2 or elements % 2:
        raise InputError(f"crank-slider: --elements must be even and >= 2, got {elements}")
    ph = system(elements, data)
    e0 = initial_state(ph, data)
    integrator = MidpointDAE(ph, dt)
    steps = round(t_end / dt)
    times, states, record, drift = integrator.run(e0, t_end, every=max(1, steps // samples),
                                                  progress=progress)
    coupler = ph.bodies["coupler"]
    mesh, na = coupler.mesh, coupler.n_axial
    ux_mid, uy_mid = mesh.p1([COUPLER / 2])[0], mesh.hermite([COUPLER / 2])[0]
    cs, ss = ph.q_slices["coupler"], ph.q_slices["slider"]
    q = states[:, :ph.n_q]
    qc = q[:, cs]
    H = np.array([ph.hamiltonian(e) for e in states])
    return CrankSliderRun(
        times=times, crank_angle=data.crank_rate * times,
        w_mid_over_l=qc[:, 3 + na:] @ uy_mid / COUPLER,
        u_mid_over_l=qc[:, 3:3 + na] @ ux_mid / COUPLER,
        coupler_angle=qc[:, 2], slider_x=q[:, ss][:, 0],
        energy_balance_error=balance_error(record, float(np.max(np.abs(H)))),
        max_constraint_drift=float(drift.max()), record=record)
