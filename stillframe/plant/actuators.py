"""Actuator models: saturation and slew-rate limits of the pendulum torque motor and the
floor-3 force actuator (scene ``actuators`` section).

A command is applied once per sample period and held (zero-order hold); the slew limit bounds
the change from the previously applied value to ``rate_limit * period``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stillframe.config import loop_sections


@dataclass
class Actuator:
    """One actuator: ``limit`` and ``rate_limit`` None mean unlimited."""

    limit: float | None
    rate_limit: float | None
    period: float
    value: float = 0.0
    limited: int = 0  # commands changed by saturation or slew limit

    def apply(self, command: float) -> float:
        """The value applied for ``command``: moved at most ``rate_limit * period`` from the last
        applied value, then clipped to ± ``limit`` (either limit None: not applied); a command
        either limit changed is counted in ``limited``."""
        target = command
        if self.rate_limit is not None:
            step = self.rate_limit * self.period
            target = min(max(target, self.value - step), self.value + step)
        if self.limit is not None:
            target = min(max(target, -self.limit), self.limit)
        if target != command:
            self.limited += 1
        self.value = target
        return target


class Actuators:
    """The pendulum torque and the floor-3 force, in the order [torque, force]."""

    def __init__(self, actuators: loop_sections.Actuators, period: float) -> None:
        a = actuators
        self.torque = Actuator(a.torque_limit, a.torque_rate_limit, period)
        self.force = Actuator(a.force_limit, a.force_rate_limit, period)

    def apply(self, command: np.ndarray) -> np.ndarray:
        """Applied [torque, force] for a commanded [torque, force]."""
        return np.array([self.torque.apply(float(command[0])), self.force.apply(float(command[1]))])

    @property
    def limited(self) -> int:
        """How many commands saturation or the slew limit changed so far, torque and force
        together."""
        return self.torque.limited + self.force.limited
