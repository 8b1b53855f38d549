"""Least-squares proportional damping (eqs. 3.208–3.213) and modal parameters / MAC (§3.3)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg

from stillframe.errors import InputError
from stillframe.identification.damping import fit_proportional_damping
from stillframe.identification.modal import mac, modal_parameters


def test_two_modes_give_the_closed_form():
    w1, w2, z1, z2 = 7.0, 31.0, 0.02, 0.011
    alpha = 2 * w1 * w2 * (z1 * w2 - z2 * w1) / (w2**2 - w1**2)
    beta = 2 * (z2 * w2 - z1 * w1) / (w2**2 - w1**2)
    assert fit_proportional_damping([w1, w2], [z1, z2]) == pytest.approx((alpha, beta), rel=1e-12)


def test_many_modes_solve_the_normal_equations():
    """Over-determined: the 2x2 normal equations, solved by Cramer's rule."""
    w = np.array([5.0, 12.0, 36.0, 55.0])
    z = np.array([0.04, 0.02, 0.012, 0.018])
    a1, a2 = 1 / (2 * w), w / 2
    s11, s12, s22 = a1 @ a1, a1 @ a2, a2 @ a2
    t1, t2 = a1 @ z, a2 @ z
    det = s11 * s22 - s12**2
    expected = ((t1 * s22 - t2 * s12) / det, (s11 * t2 - s12 * t1) / det)
    assert fit_proportional_damping(w, z) == pytest.approx(expected, rel=1e-10)


def test_thesis_alpha_beta_from_its_identified_modes():
    """Eqs. 5.173–5.176: the thesis's alpha = 0.9751, beta = -2.8815e-4 from its printed modes.
    The fit is linear in zeta, so rounding zeta to the printed digits (half a unit of the last
    digit, 5e-5) moves alpha, beta by at most sum |pinv| * 5e-5: the thesis values lie within."""
    omega = 2 * np.pi * np.array([1.934, 5.690, 8.793])
    zeta = np.array([0.0395, 0.0030, 0.0042])
    alpha, beta = fit_proportional_damping(omega, zeta)
    bound = np.abs(np.linalg.pinv(np.column_stack([1 / (2 * omega), omega / 2]))).sum(axis=1)
    bound *= 5e-5
    assert abs(alpha - 0.9751) <= bound[0]
    assert abs(beta - -2.8815e-4) <= bound[1]


def test_damping_fit_refuses_bad_input():
    with pytest.raises(InputError, match="two distinct"):
        fit_proportional_damping([3.0, 3.0], [0.01, 0.02])
    with pytest.raises(InputError, match="damping ratios"):
        fit_proportional_damping([3.0, 4.0], [0.01])
    with pytest.raises(InputError, match="positive"):
        fit_proportional_damping([-3.0, 4.0], [0.01, 0.02])


def test_modal_parameters_of_known_modes():
    """Block-diagonal continuous system with chosen frequencies, damping ratios and shapes,
    sampled exactly (expm): eqs. 3.49 and 3.58 give them back, sorted, one per pair."""
    freqs, zetas, dt = np.array([4.0, 1.5, 9.0]), np.array([0.05, 0.02, 0.001]), 0.01
    blocks = []
    for f, z in zip(freqs, zetas, strict=True):
        w = 2 * np.pi * f
        blocks.append(np.array([[0.0, 1.0], [-w * w, -2 * z * w]]))
    a_c = linalg.block_diag(*blocks)
    shapes = np.array([[1.0, 0.3, -0.5], [2.0, -1.0, 0.25]])  # sensor x mode (displacements)
    C = np.zeros((2, 6))
    C[:, 0::2] = shapes
    table = modal_parameters(linalg.expm(a_c * dt), C, dt)
    order = np.argsort(freqs)
    assert np.allclose(table.frequency_hz, freqs[order], rtol=1e-12)
    assert np.allclose(table.damping_ratio, zetas[order], rtol=1e-9)
    # normalised to the largest component: real shapes come back real, largest entry 1
    ordered = shapes[:, order]
    expected = ordered / ordered[np.argmax(np.abs(ordered), axis=0), np.arange(3)]
    assert np.allclose(table.shapes, expected, atol=1e-10)
    by_first = modal_parameters(linalg.expm(a_c * dt), C, dt, reference=0)
    assert np.allclose(by_first.shapes[0], 1.0)
    # 1.5 Hz mode, shape (0.3, -1) -> (-0.3, 1): floor 1 at magnitude 0.3, phase pi
    magnitude, phase = table.magnitude_phase(0)[0]
    assert magnitude == pytest.approx(0.3, abs=1e-10)
    assert abs(phase) == pytest.approx(np.pi, abs=1e-10)


def test_mac_values():
    rng = np.random.default_rng(0)
    a = rng.standard_normal((4, 3)) + 1j * rng.standard_normal((4, 3))
    scaled = a * np.array([2.0 - 1j, -0.3, 5j])  # complex scaling leaves MAC = 1
    assert np.allclose(np.diag(mac(a, scaled)), 1.0)
    e = np.eye(3)
    assert np.allclose(mac(e, e), np.eye(3))
    x, y = np.array([[1.0], [1.0]]), np.array([[1.0], [0.0]])
    assert mac(x, y)[0, 0] == pytest.approx(0.5)
    with pytest.raises(InputError, match="sensor count"):
        mac(np.ones((3, 2)), np.ones((2, 2)))
