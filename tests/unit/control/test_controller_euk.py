"""EUK controllers against the thesis's closed forms (eq. 5.246, 5.251) on the lumped model, the
constraint they enforce, the bounded handling of variant 1's singular configuration, and the
supervisor's enable time, saturation and watchdog."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stillframe.contract.signals import Estimate, full_inputs
from stillframe.control.euk import EUKLaw
from stillframe.control.limits import CommandLimits
from stillframe.control.supervisor import Controller
from stillframe.dynamics.models import build_model
from tests.support.scenes import lumped_scene

RNG = np.random.default_rng(11)
STATES = [np.concatenate([RNG.normal(0, 2e-3, 3), RNG.uniform(-1.2, 1.2, 1),
                          RNG.normal(0, 0.05, 3), RNG.normal(0, 2.0, 1)]) for _ in range(5)]
FORCE = 0.17


@pytest.fixture(scope="module")
def model():
    return build_model(lumped_scene())


def _thesis_terms(model, z):
    """Eq. 5.237's floor-3 force (the structure's elastic and viscous force, which for the
    thesis's dashpots is k3 x2 − k3 x3 + σ3 ẋ2 − σ3 ẋ3) and the pendulum quantities in θ."""
    q, v = z[:4], z[4:]
    theta, dtheta = q[3] + 1.5 * math.pi, v[3]
    f3 = -(model.k_struct @ q[:3] + model.c_struct @ v[:3])[2]
    m4, l4, g, s4 = model.m4, model.l4, model.g, model.r4
    J = model.pendulum_inertia
    return f3, theta, dtheta, m4, l4, g, s4, J


@pytest.mark.parametrize("z", STATES)
def test_variant_1_is_eq_5_246(model, z: np.ndarray) -> None:
    f3, th, dth, m4, l4, g, s4, J = _thesis_terms(model, z)
    thesis = (-J / (m4 * l4 * math.sin(th)) * (m4 * l4 * math.cos(th) * dth**2 + f3)
              + m4 * g * l4 * math.cos(th) + s4 * dth)
    law = EUKLaw(model, "pendulum", 1, singular_margin=1e-6)
    u, singular = law(z, FORCE)
    assert not singular
    assert u == pytest.approx(thesis, rel=1e-9)


@pytest.mark.parametrize("z", STATES)
def test_variant_2_is_eq_5_251(model, z: np.ndarray) -> None:
    f3, th, dth, m4, l4, g, s4, J = _thesis_terms(model, z)
    thesis = (-(m4 * l4 * math.cos(th) * dth**2 + f3)
              + m4 * l4 * math.sin(th) * (m4 * g * l4 * math.cos(th) + s4 * dth) / J)
    u, _ = EUKLaw(model, "floor", 1)(z, FORCE)
    assert u == pytest.approx(thesis, rel=1e-9)


@pytest.mark.parametrize("variant", ["pendulum", "floor"])
def test_command_gives_the_desired_floor_3_acceleration(model, variant: str) -> None:
    z = STATES[0]
    law = EUKLaw(model, variant, 1, hold_stiffness=400.0, hold_damping=40.0,
                 singular_margin=1e-6)
    u, _ = law(z, FORCE)
    control = np.array([u, 0.0]) if variant == "pendulum" else np.array([0.0, u])
    a = model.accelerations(z[:4], z[4:], full_inputs(control, FORCE, 1))
    assert a[2] == pytest.approx(-40.0 * z[6] - 400.0 * z[2], rel=1e-6)


def test_variant_1_is_bounded_and_flagged_at_the_singular_configuration(model) -> None:
    law = EUKLaw(model, "pendulum", 1, singular_margin=0.02)
    rest = abs(law.gain(np.zeros(4)))
    peaks = []
    for phi in np.linspace(math.pi / 2 - 0.05, math.pi / 2 + 0.05, 41):
        z = STATES[1].copy()
        z[3] = phi
        u, singular = law(z, FORCE)
        error = abs(model.accelerations(z[:4], z[4:], full_inputs(np.zeros(2), FORCE, 1))[2])
        assert math.isfinite(u)
        assert abs(u) <= error / (2 * 0.02 * rest) * (1 + 1e-9)  # the damped inverse's bound
        peaks.append(abs(u))
        assert singular == (abs(law.gain(z[:4])) < 0.02 * rest)
    z = STATES[1].copy()
    z[3] = math.pi / 2
    assert law(z, FORCE) == (pytest.approx(0.0, abs=1e-9), True)
    # the exact inverse (eq. 5.246) grows without bound there
    exact = EUKLaw(model, "pendulum", 1, singular_margin=1e-6)
    z[3] = math.pi / 2 - 1e-4
    assert abs(exact(z, FORCE)[0]) > 100 * max(peaks)


def _supervisor(limit=None, start=1.0):
    return Controller(lambda z, f: (float(z[0] * 1e3), False), actuator=1, period=0.01,
                      start=start, limits=CommandLimits(limit=limit), watchdog_periods=3)


def _estimate(t: float, value: float = 1e-3) -> Estimate:
    z = np.full(8, value)
    return Estimate(t, z, z)


def test_supervisor_enable_time_and_saturation() -> None:
    c = _supervisor(limit=0.5)
    assert c.command(0.99, _estimate(0.99), 0.0).force == 0.0
    on = c.command(1.0, _estimate(1.0), 0.0)
    assert on.enabled and on.force == 0.5
    assert on.saturated and c.counters.saturated == 1
    assert on.t == 1.0 and on.torque == 0.0


def test_watchdog_zeroes_the_command_without_a_fresh_estimate() -> None:
    c = _supervisor(start=0.0)
    assert c.command(1.00, _estimate(1.00), 0.0).force == pytest.approx(1.0)
    assert c.command(1.02, None, 0.0).force == pytest.approx(1.0)  # 2 periods: still fresh
    tripped = c.command(1.03, None, 0.0)
    assert tripped.watchdog and tripped.force == 0.0 and c.counters.watchdog == 1
    assert c.command(1.04, _estimate(0.5), 0.0).watchdog  # an older estimate does not help
    back = c.command(1.05, _estimate(1.05, 2e-3), 0.0)
    assert not back.watchdog and back.force == pytest.approx(2.0)


def test_non_finite_law_output_gives_zero() -> None:
    c = Controller(lambda z, f: (float("nan"), False), actuator=0, period=0.01)
    out = c.command(0.0, _estimate(0.0), 0.0)
    assert out.torque == 0.0 and out.singular
