"""What a command may be: the actuator's torque and slew limits and the pendulum angle the design
model is valid for (scene ``actuators.torque_limit``, ``actuators.torque_rate_limit``,
``controller.limit``, ``controller.angle_limit``), shared by the anti-windup LQG
(:class:`~stillframe.control.lqg.ConditionedLQGLaw`) and the MPC (:mod:`stillframe.control.mpc`).

Why the angle: the rig's pendulum is light (m₄ g L₄ = 0.067 N m on the thesis rig), so a torque
of 2 N m held for one 31 ms period turns it by ≈ 0.35 rad and a few such periods carry it over
the top, where the linearised design model no longer says anything. A limit on the predicted
angle keeps the loop where its model holds; a limit on the torque alone does not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stillframe.config.scene import Scene


@dataclass(frozen=True)
class CommandLimits:
    """|u| ≤ ``torque`` (None: none), |u − u_prev| ≤ ``step`` per period (None: none),
    |φ| ≤ ``angle`` [rad] over the prediction (None: none)."""

    torque: float | None
    step: float | None
    angle: float | None

    @classmethod
    def of(cls, scene: Scene) -> CommandLimits:
        """The pendulum torque's limits of the scene: the tighter of the actuator's saturation
        and ``controller.limit``, its slew limit over one sample period, the angle limit."""
        bounds = [b for b in (scene.actuators.torque_limit, scene.controller.limit) if b]
        rate = scene.actuators.torque_rate_limit
        return cls(min(bounds) if bounds else None,
                   None if rate is None else rate / scene.sensors.rate_hz,
                   scene.controller.angle_limit)

    def actuator_interval(self, previous: float) -> tuple[float, float]:
        """The commands the actuator applies unchanged after ``previous``."""
        lo, hi = -np.inf, np.inf
        if self.torque is not None:
            lo, hi = -self.torque, self.torque
        if self.step is not None:
            lo, hi = max(lo, previous - self.step), min(hi, previous + self.step)
        return lo, hi


def condition(u: float, limits: CommandLimits, previous: float, free_angle: float,
              angle_gain: float) -> tuple[float, bool]:
    """``u`` moved to the nearest command that the actuator applies unchanged and that keeps the
    predicted angle ``free_angle + angle_gain · u`` within ±``limits.angle``; where no command
    does both, the actuator's command nearest to the angle interval. Returns the command and
    whether it was changed."""
    lo, hi = limits.actuator_interval(previous)
    if limits.angle is not None and angle_gain != 0.0:
        a, b = sorted(((-limits.angle - free_angle) / angle_gain,
                       (limits.angle - free_angle) / angle_gain))
        if max(lo, a) <= min(hi, b):
            lo, hi = max(lo, a), min(hi, b)
        else:  # the angle interval lies beyond what the actuator can do: its nearest end
            lo = hi = hi if b > hi else lo
    value = min(max(u, lo), hi)
    return value, value != u
