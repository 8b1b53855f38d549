"""The thesis's hammer test (§5.5) on the simulated lumped model: impulse on floor 1, three floor
accelerations, 32 Hz, 2048 samples, sensor noise; OKID + ERA/DC of order 6 as in the thesis.

:func:`stillframe.identification.hammer.hammer_test` samples the linearised lumped model (pendulum
included,
the scene's Rayleigh damping) exactly. Noise: 1e-3 m/s^2 rms on each accelerometer (0.1 mg,
piezoelectric class) and 1e-3 N rms on the load cell (16-bit converter over ±50 N), against
peak accelerations near 1.2 m/s^2. References: the model's own continuous eigenvalues.

The model has four modes; the pendulum's (1.10 Hz, ζ = 0.124) contributes about 1e-3 of the
others' resonance peaks to the floor accelerations, so it is buried in the noise, and the thesis
too identified order 6 (three structural modes). The three structural modes are checked.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from stillframe.config.scene import load_scene
from stillframe.dynamics.models import build_model
from stillframe.identification.damping import fit_proportional_damping, proportional_damping_matrix
from stillframe.identification.hammer import SCENE, hammer_test
from stillframe.identification.mkr import mkr
from stillframe.identification.modal import mac, modal_parameters
from stillframe.identification.pipeline import identify
from stillframe.identification.stabilization import stabilization_diagram
from stillframe.locations import REPO_ROOT


@pytest.fixture(scope="module")
def lumped():
    return build_model(load_scene(SCENE)).linearized()


@pytest.mark.parametrize("method", ["okid-eradc", "okid-era"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_hammer_identification_within_thesis_tolerances(lumped, method, seed):
    rec = hammer_test(lumped, seed)
    ident = identify(rec.u, rec.y, rec.dt, method, 6)
    assert np.allclose(ident.modes.frequency_hz, rec.frequency_hz[1:], rtol=5e-3, atol=0)
    assert np.allclose(ident.modes.damping_ratio, rec.damping_ratio[1:], rtol=0.10, atol=0)
    # shapes at the three floors against the exact model's
    exact = modal_parameters(rec.model[0], rec.model[2], rec.dt)
    assert np.min(np.diag(mac(exact.shapes[:, 1:], ident.modes.shapes))) > 0.999


def test_auto_order_is_the_thesis_order_and_alpha_beta_follow(lumped):
    rec = hammer_test(lumped, 0)
    ident = identify(rec.u, rec.y, rec.dt, "okid-eradc", "auto")
    assert ident.order == 6
    assert ident.order_gap > 10.0
    # proportional damping (eq. 3.213) from the identified modes against the same fit to the
    # model's exact structural modes
    alpha, beta = fit_proportional_damping(ident.modes.omega, ident.modes.damping_ratio)
    alpha0, beta0 = fit_proportional_damping(2 * np.pi * rec.frequency_hz[1:],
                                             rec.damping_ratio[1:])
    assert alpha == pytest.approx(alpha0, rel=0.05)
    assert beta == pytest.approx(beta0, rel=0.05)


def test_stabilization_diagram_keeps_the_structural_modes(lumped):
    """From order 8 to 24 the three structural modes are flagged stable (1 % in frequency, 5 %
    in damping, MAC 0.98 against the previous order) at their true frequencies."""
    rec = hammer_test(lumped, 1)
    ident = identify(rec.u, rec.y, rec.dt, "okid-eradc", 6)
    rows = stabilization_diagram(ident.factorization, rec.dt, range(6, 25, 2))
    assert [row.order for row in rows] == list(range(6, 25, 2))
    for row in rows[1:]:
        stable = row.modes.frequency_hz[row.stable]
        for f in rec.frequency_hz[1:]:
            assert np.min(np.abs(stable / f - 1.0)) < 5e-3, (row.order, f)


def test_the_combined_variant_is_less_accurate_in_damping(lumped):
    """The thesis's combined [Y, Y0] realization (eq. 3.203) on the same records: frequencies
    still within 0.5 %, but the first mode's damping ratio 15–19 % low (why it is not the
    default)."""
    for seed in range(3):
        rec = hammer_test(lumped, seed)
        ident = identify(rec.u, rec.y, rec.dt, "okid-eradc", 6, combined=True)
        assert np.allclose(ident.modes.frequency_hz, rec.frequency_hz[1:], rtol=5e-3, atol=0)
        assert ident.modes.damping_ratio[0] < 0.9 * rec.damping_ratio[1]


@pytest.mark.processes
@pytest.mark.slow
def test_hammer_table_command():
    """``python -m stillframe.identification.hammer`` prints one row per identified mode and
    variant."""
    root = REPO_ROOT
    out = subprocess.run([sys.executable, "-m", "stillframe.identification.hammer", "--seeds", "1"],
                         cwd=root, capture_output=True, text=True, check=True).stdout
    rows = [line.split() for line in out.splitlines()[2:]]
    plain = [row for row in rows if "combined" not in row]
    assert len(rows) == 9 and len(plain) == 6
    assert all(abs(float(row[4])) < 0.5 and abs(float(row[7])) < 10.0 for row in plain)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mkr_after_the_hammer_test_recovers_the_floors(lumped, seed):
    """The thesis's identify-then-MKR loop (§5.5) on the simulated rig: M and K of the three
    floors within 1 % of the model's largest entry; floor 3's mass lies between the floor alone
    (1.380 kg) and floor plus pendulum (1.463 kg), which moves partly with it. R = αM + βK with
    α, β fitted to the identified modes (eq. 3.242) within 15 % of the model's largest damping
    entry (MKR's own R is noisier, as the thesis found)."""
    rec = hammer_test(lumped, seed)
    ident = identify(rec.u, rec.y, rec.dt, "okid-eradc", 6)
    phys = mkr(ident.A, ident.B, ident.C, rec.dt, [0, 1, 2], [0], "acceleration")
    mass, stiffness, damping = lumped.mass[:3, :3], lumped.stiffness[:3, :3], lumped.damping[:3, :3]
    assert np.allclose(np.diag(phys.M)[:2], np.diag(mass)[:2], rtol=1e-2)
    assert 1.380 * 0.99 < phys.M[2, 2] < 1.463 * 1.01
    assert np.max(np.abs(phys.M - np.diag(np.diag(phys.M)))) < 1e-2 * np.max(mass)
    assert np.max(np.abs(phys.K - stiffness)) < 1e-2 * np.max(stiffness)
    alpha, beta = fit_proportional_damping(ident.modes.omega, ident.modes.damping_ratio)
    rayleigh = proportional_damping_matrix(phys.M, phys.K, alpha, beta)
    assert np.max(np.abs(rayleigh - damping)) < 0.15 * np.max(damping)
