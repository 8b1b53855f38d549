"""Sensor models of the rig: floor accelerometers (noise, bias), the pendulum encoder
(quantised angle, optional noise), the load cell under the shaker (noise).

Each reading is one sample at the sensor rate; the noise comes from a seeded generator so that
the same scene and seed give the same readings in one process and across nodes.
"""

from __future__ import annotations

import numpy as np

from stillframe.config import loop_sections


def quantise(angle: float, resolution: float) -> float:
    """The encoder's reading: the nearest multiple of ``resolution`` (exact when 0)."""
    return angle if resolution <= 0 else resolution * round(angle / resolution)


class Sensors:
    """Turns the true floor accelerations, φ and excitation force into readings."""

    def __init__(self, sensors: loop_sections.Sensors, rng: np.random.Generator) -> None:
        self.config = sensors
        self.rng = rng
        self.bias = np.asarray(sensors.accelerometer_bias, dtype=float)

    def read(self, accelerations: np.ndarray, phi: float,
             force: float) -> tuple[np.ndarray, float]:
        """[a1, a2, a3, φ] readings and the load-cell reading."""
        c = self.config
        noise = self.rng.standard_normal(5)
        out = np.empty(4)
        out[:3] = accelerations + self.bias + c.accelerometer_noise_std * noise[:3]
        out[3] = quantise(phi + c.encoder_noise_std * noise[3], c.encoder_resolution)
        return out, float(force + c.load_cell_noise_std * noise[4])
