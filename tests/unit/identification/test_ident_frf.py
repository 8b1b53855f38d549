"""H1 FRF with coherence against the exact transfer function (python-control) and the closed-form
coherence of a known signal-to-noise ratio."""

from __future__ import annotations

import control
import numpy as np
import pytest

from stillframe.errors import IdentificationError, InputError
from stillframe.identification.frf import h1_frf, model_frf
from tests.support.ident_systems import MASS, STIFFNESS, continuous, discrete, simulate

DT = 0.02
DAMPED = 2.0 * MASS + 1e-2 * STIFFNESS  # damping ratios 10–20 %: little leakage bias


def mimo_system():
    b2 = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    return discrete(*continuous(MASS, STIFFNESS, DAMPED, b2, "displacement"), DT)


def test_mimo_h1_matches_the_exact_transfer_function():
    """Two white inputs, three outputs: every entry of H1 against python-control's frequency
    response of the same discrete system, relative to that entry's peak."""
    A, B, C, D = mimo_system()
    u = np.random.default_rng(2).standard_normal((2**17, 2))
    y = simulate(A, B, C, D, u)
    y += 1e-8 * np.random.default_rng(3).standard_normal(y.shape)  # high SNR up to 20 Hz
    frf = h1_frf(u, y, DT, nperseg=2048)
    sys = control.ss(A, B, C, D, DT)
    band = (frf.frequency_hz > 0.2) & (frf.frequency_hz < 20.0)
    exact = control.frequency_response(sys, 2 * np.pi * frf.frequency_hz[band])
    response = np.transpose(exact.complex, (2, 0, 1))  # (F, outputs, inputs)
    error = np.abs(frf.H[band] - response) / np.max(np.abs(response), axis=0)
    # what remains is the random error of responses leaking across segment edges (~3 %)
    assert np.max(error) < 0.05
    assert np.min(frf.coherence[band]) > 0.95
    assert np.allclose(model_frf(A, B, C, D, DT, frf.frequency_hz[band]), response, atol=1e-12)


def test_coherence_follows_the_signal_to_noise_ratio():
    """White input of variance 1, white output noise of variance s^2: the coherence is
    |H|^2 / (|H|^2 + s^2) (one-sided spectra of both are flat). 2047 averages put the random
    error of the estimate near 0.01; the partially coherent band lies above the modes."""
    A, B, C, D = mimo_system()
    rng = np.random.default_rng(4)
    u = rng.standard_normal((2**17, 1))
    clean = simulate(A, B[:, :1], C[:1], D[:1, :1], u)
    noise = 1e-4
    frf = h1_frf(u, clean + noise * rng.standard_normal(clean.shape), DT, nperseg=128)
    gain2 = np.abs(model_frf(A, B[:, :1], C[:1], D[:1, :1], DT, frf.frequency_hz))[:, 0, 0] ** 2
    expected = gain2 / (gain2 + noise**2)
    mid = (expected > 0.2) & (expected < 0.95)
    assert np.count_nonzero(mid) > 20
    assert np.max(np.abs(frf.coherence[mid, 0] - expected[mid])) < 0.05


def test_h1_refuses_bad_records():
    u = np.random.default_rng(0).standard_normal((1000, 2))
    with pytest.raises(InputError, match="samples"):
        h1_frf(u, u[:-1], DT)
    with pytest.raises(IdentificationError, match="singular"):
        h1_frf(np.column_stack([u[:, 0], u[:, 0]]), u, DT)  # two identical inputs
    with pytest.raises(InputError, match="segment"):
        h1_frf(u, u, DT, nperseg=4000)
