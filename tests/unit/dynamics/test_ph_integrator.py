"""AVF implicit midpoint on the pHDAE: discrete power balance, constraint drift, order 2 against
scipy's Radau on the index-1 form."""

import numpy as np
import pytest

from stillframe.dynamics.ph.body import BeamSection, floating_beam, rigid_body
from stillframe.dynamics.ph.integrator import NEWTON_TOL, MidpointDAE, balance_error
from stillframe.dynamics.ph.joints import Link, Support, fixed
from stillframe.dynamics.ph.reference import radau_reference
from stillframe.dynamics.ph.system import PHSystem, RotaryDamper

G = 9.81


def double_pendulum(damping: float = 0.0) -> tuple[PHSystem, np.ndarray]:
    """Two rigid links on revolute joints, released from a large angle with spin."""
    links = [rigid_body(f"l{i}", 0.5, 0.5 * 0.3**2 / 12, 0.15, {"P": 0.0, "C": 0.3}, gravity=G)
             for i in (1, 2)]
    joints = [Support(("l1", "P"), (0, 1), fixed([0, 0])), Link(("l1", "C"), ("l2", "P"), (0, 1))]
    dampers = [RotaryDamper(("l2", "P"), ("l1", "C"), damping)] if damping else []
    system = PHSystem(links, joints, dampers=dampers)
    q = np.array([0, 0, 0.4, 0.3, 0.0, -1.2])
    q = system.assemble(q)
    nu = system.consistent_velocity(q, np.array([0, 0, 1.0, 0, 0, -2.0]))
    return system, system.state(q, nu)


def flexible_arm(damping: float) -> tuple[PHSystem, np.ndarray]:
    """A flexible beam on a lossy revolute joint to ground, a rigid body pinned at its tip."""
    section = BeamSection(2714.0 * 4.0645e-5, 7.1e10 * 4.0645e-5, 0.616)
    beam = floating_beam("beam", 0.28, section, 3, "cantilever", lumped_mass=0.01, gravity=G)
    tip = rigid_body("tip", 0.05, 2e-4, 0.05, {"P": 0.0}, gravity=G)
    joints = [Support(("beam", "P"), (0, 1), fixed([0, 0])),
              Link(("beam", "C"), ("tip", "P"), (0, 1))]
    system = PHSystem([beam, tip], joints, dampers=[RotaryDamper(("tip", "P"), ("beam", "C"),
                                                                 damping)])
    q = np.zeros(system.n_q)
    q[system.q_slices["beam"]][2] = -0.3
    q[system.q_slices["tip"]][:3] = [0.28 * np.cos(-0.3), 0.28 * np.sin(-0.3), -1.0]
    q = system.assemble(q)
    guess = np.zeros(system.n_q)
    guess[system.q_slices["beam"]][2], guess[system.q_slices["tip"]][2] = 2.0, -3.0
    return system, system.state(q, system.consistent_velocity(q, guess))


def test_discrete_power_balance_holds_to_round_off_with_gravity_and_a_damper():
    """The AVF balance is exact at each step's Newton solution. Newton stops once its correction
    is below NEWTON_TOL of the state and contracts by ≥ 4 per iteration (else it refactors), so
    a step's balance residual is below NEWTON_TOL·H, and the run's sum below steps times that.
    The drift (m) adds per step the rounding of q (u·|q| ≈ 1e-16) and h times the velocity
    constraint's residual: 50 steps stay below 1e-13 m."""
    system, e0 = flexible_arm(damping=0.002)
    _, states, record, drift = MidpointDAE(system, 2e-4).run(e0, 0.01)
    scale = abs(system.hamiltonian(e0))
    assert balance_error(record, scale) < NEWTON_TOL
    dissipated = np.sum(record.dissipated)
    assert dissipated > 1e-3 * scale  # the damper works, and the balance accounts for it exactly
    H = [system.hamiltonian(e) for e in states]
    assert abs((H[-1] - H[0]) + dissipated) < len(record.delta_h) * NEWTON_TOL * scale
    assert drift.max() < 1e-13


@pytest.mark.slow
def test_midpoint_is_second_order_against_radau_on_the_index1_form():
    system, e0 = double_pendulum()
    errors = []
    for h in (0.01, 0.005):
        t, states, _, _ = MidpointDAE(system, h).run(e0, 0.5)
        ref = radau_reference(system, e0, t[[0, -1]])
        errors.append(np.max(np.abs(states[-1] - ref[-1])))
    assert errors[1] < 0.05
    assert 3.5 < errors[0] / errors[1] < 4.5


def drift_run(steps: int) -> tuple[float, float]:
    system, e0 = double_pendulum(damping=0.01)
    h = 2e-3
    _, _, record, drift = MidpointDAE(system, h).run(e0, steps * h, every=steps // 10)
    return float(drift.max()), balance_error(record, abs(system.hamiltonian(e0)))


def test_constraint_drift_and_balance_stay_at_round_off():
    drift, balance = drift_run(500)
    assert drift < 1e-13
    assert balance < 1e-13


@pytest.mark.long
def test_constraint_drift_stays_bounded_over_1e5_steps():
    """Each step adds the rounding of g's terms (u times the two 0.3 m links) and h times the
    velocity constraint's Newton residual (h·NEWTON_TOL·|ν|, smaller): each below u·0.6 m, so
    linear in the steps at worst (a random walk, √steps of it, in practice); a scheme that lets
    positions drift adds truncation terms of order h³ per step, ≫ that."""
    steps = 100_000
    drift, balance = drift_run(steps)
    assert drift < steps * 2 * 0.6 * np.finfo(float).eps / 2
    assert balance < 1e-12
