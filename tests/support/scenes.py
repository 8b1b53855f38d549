"""Scenes and data shared by the closed-loop tests."""

from __future__ import annotations

import numpy as np
from scipy import optimize

from stillframe.config.scene import Scene, load_scene, scene_from_dict
from stillframe.contract.signals import Sample
from stillframe.locations import REPO_ROOT

ROOT = REPO_ROOT


def thesis_scene(name: str, overrides: list[str] | None = None) -> Scene:
    return load_scene(ROOT / "scenes" / f"{name}.yaml", overrides)


def lumped_scene(overrides: list[str] | None = None) -> Scene:
    """Lumped rig, harmonic forcing, 32 Hz sensors with the thesis's noise levels."""
    return scene_from_dict({
        "name": "lumped_loop",
        "excitation": {"type": "harmonics"},
        "integrator": {"method": "rk4", "dt": 1.0 / 256},
        "sensors": {"rate_hz": 32.0, "accelerometer_noise_std": 1e-3, "encoder_noise_std": 1e-3},
        "duration": 20.0,
    }, overrides)


def sample(t: float, y: np.ndarray, force: float = 0.0,
           present: np.ndarray | None = None) -> Sample:
    return Sample(t, np.asarray(y, dtype=float), force,
                  np.ones(5, dtype=bool) if present is None else present)


def characteristic_frequencies(scene: Scene) -> np.ndarray:
    """The lumped rig's undamped frequencies [Hz] linearised at rest, from the thesis's
    matrices (eq. 5.41–5.43, 5.59–5.66) assembled here and the roots of d(λ) = det(K − λM), a
    quartic in λ = ω²: located by the polynomial through five values of d, then each refined by
    Brent's method on d itself within ±2 % of it. A second assembly and a second solver,
    independent of the model's code and of the symmetric eigensolver ``modes`` uses."""
    rig = scene.rig
    c, p = rig.columns, rig.pendulum
    k = (c.per_story * 12 * c.youngs_modulus * c.width * c.thickness**3 / 12
         * np.array(c.stiffness_factors) / np.array(c.lengths) ** 3)
    m1, m2, m3 = rig.floor_masses
    coupling = p.mass * p.half_length
    M = np.array([[m1, 0, 0, 0], [0, m2, 0, 0], [0, 0, m3 + p.mass, coupling],
                  [0, 0, coupling, p.mass * p.half_length**2 + p.inertia]])
    K = np.array([[k[0] + k[1], -k[1], 0, 0], [-k[1], k[1] + k[2], -k[2], 0],
                  [0, -k[2], k[2], 0], [0, 0, 0, p.mass * rig.gravity * p.half_length]])

    def d(x: float) -> float:
        return float(np.linalg.det(K - x * M))

    nodes = np.linspace(0, 4e4, 5)
    guesses = np.sort(np.roots(np.polyfit(nodes, [d(x) for x in nodes], 4)).real)
    roots = [optimize.brentq(d, 0.98 * g, 1.02 * g, xtol=1e-300, rtol=4 * np.finfo(float).eps)
             for g in guesses]
    return np.sqrt(roots) / (2 * np.pi)
