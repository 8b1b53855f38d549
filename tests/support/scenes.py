"""Scenes and data shared by the closed-loop tests."""

from __future__ import annotations

import numpy as np

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
