"""The passivity inequality of the passivity controller, W_act(t) ≤ ½k_p(φ(t_s)² − φ(t)²),
against closed forms of a continuous passive law and of one that supplies energy."""

import numpy as np
import pytest

from stillframe.loop.energy_balance import PassivityCheck
from tests.support.scenes import thesis_scene

KP, T = 0.5, 1 / 32


def run(phi: np.ndarray, p_act: np.ndarray, start: float = 0.0) -> PassivityCheck:
    scene = thesis_scene("ph_passivity", ["controller.shaping_stiffness=0.5",
                                          f"controller.start={start}", "evaluation.window=0.1"])
    check = PassivityCheck(scene, T)
    for k, (angle, power) in enumerate(zip(phi, p_act, strict=True)):
        check.update(k * T, np.array([1.0, 0.0, power, 0.0, 0.0]), angle)
    return check


def test_storage_released_bounds_the_supplied_energy():
    """φ(t) = a cos ωt under u = −k_p φ alone: the port power is −k_p φ φ̇, and its energy over a
    period equals ½k_p(φ₀² − φ(t)²) exactly: never more (no violation)."""
    t = np.arange(200) * T
    a, w = 0.1, 3.0
    phi = a * np.cos(w * t)
    # mean power over [t_{k−1}, t_k] of −k_p φ φ̇ = −½k_p d(φ²)/dt: the exact increments
    p = np.concatenate([[0.0], -0.5 * KP * np.diff(phi**2) / T])
    check = run(phi, p, start=0.1)      # storage taken at the first sample t_s ≥ 0.1 s
    s = 4
    assert check.violations == 0
    assert check.supplied == pytest.approx(0.5 * KP * (phi[s] ** 2 - phi[-1] ** 2), abs=1e-15)
    assert check.allowed == pytest.approx(check.supplied, abs=1e-15)


def test_energy_beyond_the_storage_is_counted_from_the_controller_start():
    t = np.arange(100) * T
    phi = np.full(t.size, 0.2)                       # storage constant: allows nothing
    p = np.where(t >= 1.0, 1e-3, 0.0)                # 1 mW supplied from t = 1 s
    check = run(phi, p, start=0.5)
    supplied_after = np.sum(T * p)
    assert check.violations == np.sum(t >= 1.0)   # storage at t = 0.5 s, power from 1 s
    assert check.first_violation_t == pytest.approx(1.0)
    assert check.excess_max == pytest.approx(supplied_after)
    assert check.message().startswith("passivity: the controller supplied up to")
