"""The identification test's force, chosen before anything runs, so that ``experiment`` works on
every closed-loop scene.

A plant with process noise (``plant.process_noise_std``, eq. 5.215: increments added to the
physical state once per sample) is driven by that noise as well as by the test's force. The
force is the only input the identification sees; what the noise drives is, to it, output noise.
On ``scenes/thesis_lqg.yaml`` (1e-3 on every state) the noise drives the floor accelerations far
above the response to the default 0.1 N, and the identified model is noise (MKR then gives a mass
matrix that is not positive definite). Both responses are linear in their sources, so their ratio
is known before the test from the plant's linearised model, sampled with a zero-order hold:
``X_f = A X_f Aᵀ + B_f B_fᵀ`` (unit force held over each period), ``X_w = A X_w Aᵀ + diag(σ²)``,
and each floor's acceleration variance ``C X Cᵀ (+ D Dᵀ)``. :func:`required_force` is the force
std whose response stands :data:`TEST_SNR_DB` above the noise's on every floor.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import linalg, signal

from stillframe.config.schema import Section
from stillframe.design.identified import frame_for
from stillframe.errors import InputError

TEST_SNR_DB = 10.0
"""The forced response's margin over the process noise's, per floor (variance ratio 10; at 0 dB,
2 N on thesis_lqg, M came within 1.6 % but with a weak-order-gap warning)."""
DEFAULT_FORCE = 0.1
"""The test force [N] of a plant without process noise."""


def required_force(scene: Section) -> float | None:
    """The force std [N] the test needs against the plant's process noise (module docstring);
    None without process noise, or for a plant whose state is not the eight physical states the
    noise is added to."""
    sigma = np.asarray(scene.plant.process_noise_std, dtype=float)
    if not sigma.any():
        return None
    model = frame_for(scene.plant.model, scene.plant.file, scene, "plant.file")
    lin = model.linearized()
    a_c, b_c = lin.state_space()
    n = lin.mass.shape[0]
    if 2 * n != sigma.size:
        return None
    rows = n + model.floor_index
    c, d = a_c[rows], b_c[rows][:, :1]
    period = 1.0 / scene.sensors.rate_hz
    a, b, *_ = signal.cont2discrete((a_c, b_c[:, :1], c, d), period, method="zoh")
    forced = np.diag(c @ linalg.solve_discrete_lyapunov(a, b @ b.T) @ c.T + d @ d.T)
    noise = np.diag(c @ linalg.solve_discrete_lyapunov(a, np.diag(sigma**2)) @ c.T)
    return math.sqrt(10 ** (TEST_SNR_DB / 10) * float(np.max(noise / forced)))


def noise_margin_db(scene: Section, force: float) -> float:
    """How far (dB) the response to ``force`` stands above the process noise's on the worst
    floor; inf without process noise."""
    need = required_force(scene)
    if need is None:
        return math.inf
    return TEST_SNR_DB + 20 * math.log10(force / need)


def test_force(scene: Section, asked: float | None) -> float:
    """The test's force std: ``asked``, or the larger of :data:`DEFAULT_FORCE` and
    :func:`required_force`. An ``asked`` force too weak for the process noise is refused before
    anything runs, with the margin and the force that would do."""
    need = required_force(scene)
    if asked is None:
        return DEFAULT_FORCE if need is None else max(DEFAULT_FORCE, need)
    if need is not None and asked < need:
        sigma = max(scene.plant.process_noise_std)
        above = -noise_margin_db(scene, asked) + TEST_SNR_DB
        raise InputError(
            f"--test-force {asked:g} N: the plant's process noise (plant.process_noise_std up to "
            f"{sigma:g} per sample) drives the floor accelerations {above:.0f} dB above this "
            f"force's response, which then cannot be identified; give at least "
            f"{need:.3g} N ({TEST_SNR_DB:g} dB above the noise), or leave --test-force out")
    return asked
