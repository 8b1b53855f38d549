"""The thesis's own identified model of the rig (§5.5, eqs. 5.168–5.179): modal parameters and
MKR of the printed Â, B̂, Ĉ reproduce the printed modes and M̂, K̂, R̂. The matrices are printed to
four decimals or significant digits, which bounds the agreement."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.errors import IdentificationError
from stillframe.identification.mkr import mkr
from stillframe.identification.modal import modal_parameters

DT = 1.0 / 32.0
A = np.array([
    [0.4374, 0.8852, -0.0220, -0.0415, -0.0017, -0.0002],
    [-0.9029, 0.4310, -0.0875, 0.0191, -0.0040, 0.0010],
    [0.0500, -0.0111, -0.1490, 0.9742, -0.0041, -0.0021],
    [0.0621, -0.0617, -0.9841, -0.1538, -0.0067, 0.0009],
    [-0.0146, -0.0241, -0.0015, -0.0312, 0.9230, 0.3530],
    [-0.0148, -0.0340, 0.0100, -0.0425, -0.3777, 0.9070],
])  # eq. 5.168
B = np.array([[-0.0946], [-0.0203], [-0.1133], [0.0030], [-0.0885], [-0.1079]])  # eq. 5.169
C = np.array([
    [-26.355, 7.736, -5.170, -1.132, -0.677, 0.162],
    [-4.217, 2.626, 14.217, 1.220, -1.340, 0.307],
    [11.219, -4.228, -5.732, -0.055, -1.549, 0.470],
])  # eq. 5.170


def test_modes_of_the_thesis_model():
    """Eqs. 5.173–5.175: f, ζ and shapes ρ e^{iθ} normalised to floor 1."""
    table = modal_parameters(A, C, DT, reference=0)
    assert np.allclose(table.frequency_hz, [1.934, 5.690, 8.793], atol=1.5e-3)
    assert np.allclose(table.damping_ratio, [0.0395, 0.0030, 0.0042], atol=2e-4)
    rho = np.array([[1, 2.503, 2.851], [1, 0.1492, 0.4221], [1, 3.443, 1.476]]).T
    theta = np.array([[0, -0.0186, -0.1053], [0, -0.0365, -3.170], [0, -3.144, -0.0296]]).T
    assert np.allclose(np.abs(table.shapes), rho, rtol=3e-3)
    wrapped = np.angle(np.exp(1j * (np.angle(table.shapes) - theta)))
    assert np.max(np.abs(wrapped)) < 2e-3


def test_mkr_of_the_thesis_model():
    """Eqs. 5.177–5.179. The printed D̂ (eq. 5.171) has D̂₁ = −2.574 < 0, i.e. the load cell's
    sign is opposite to the accelerometers' (D = C_a M⁻¹ B₂ > 0 for floor 1): as printed, MKR
    refuses (a negative mass); with the force sign corrected it gives the thesis's matrices."""
    with pytest.raises(IdentificationError, match="sign"):
        mkr(A, B, C, DT, [0, 1, 2], [0])
    model = mkr(A, -B, C, DT, [0, 1, 2], [0])
    M = np.array([[0.3871, -0.0156, 0.0011], [-0.0156, 0.2621, -0.0323],
                  [0.0011, -0.0323, 0.3790]])
    K = np.array([[534.061, -221.931, 25.696], [-221.931, 614.564, -432.792],
                  [25.696, -432.792, 422.005]])
    R = np.array([[9.960, -4.823, 1.018], [-4.823, 12.480, -8.366], [1.018, -8.366, 7.017]])
    for got, printed in ((model.M, M), (model.K, K), (model.R, R)):
        assert np.max(np.abs(got - printed)) <= 2e-3 * np.max(np.abs(printed))
