"""What a command may be: the actuator's saturation and slew limits, the controller's limit and
the pendulum angle the design model is valid for (scene ``actuators.torque_limit``,
``actuators.torque_rate_limit`` or their floor-3 force twins, ``controller.limit``,
``controller.angle_limit``), held once here and shared by the supervisor
(:class:`~stillframe.control.supervisor.Controller`), the anti-windup LQG
(:class:`~stillframe.control.lqg.ConditionedLQGLaw`) and the MPC (:mod:`stillframe.control.mpc`).
The controller's limit can change while the loop runs (controller_node's ``command_limit``):
:meth:`CommandLimits.with_limit`, taken by every law at its next sample.

Why the angle: the rig's pendulum is light (m₄ g L₄ = 0.067 N m on the thesis rig), so a torque
of 2 N m held for one 31 ms period turns it by ≈ 0.35 rad and a few such periods carry it over
the top, where the linearised design model no longer says anything. A limit on the predicted
angle keeps the loop where its model holds; a limit on the torque alone does not.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract.signals import FORCE, actuator_of

__all__ = ["CommandLimits", "condition"]


@dataclass(frozen=True, kw_only=True)
class CommandLimits:
    """|u| ≤ :attr:`magnitude` (the tighter of the actuator's ``saturation`` and the controller's
    ``limit``; None: none), |u − u_prev| ≤ ``step`` per period (None: none), |φ| ≤ ``angle``
    [rad] over the prediction (None: none)."""

    saturation: float | None = None
    limit: float | None = None
    step: float | None = None
    angle: float | None = None

    @classmethod
    def of(cls, scene: Scene) -> CommandLimits:
        """The limits of the command of the scene's controller: its actuator's saturation and
        slew limit (over one sample period), ``controller.limit``, ``controller.angle_limit``."""
        a = scene.actuators
        saturation, rate = ((a.force_limit, a.force_rate_limit) if actuator_of(scene) == FORCE
                            else (a.torque_limit, a.torque_rate_limit))
        return cls(saturation=saturation, limit=scene.controller.limit,
                   step=None if rate is None else rate / scene.sensors.rate_hz,
                   angle=scene.controller.angle_limit)

    @property
    def magnitude(self) -> float | None:
        """The largest |u|: the tighter of ``saturation`` and ``limit`` (None or 0: none)."""
        bounds = [b for b in (self.saturation, self.limit) if b]
        return min(bounds) if bounds else None

    def with_limit(self, limit: float | None) -> CommandLimits:
        """The same limits with the controller's ``limit`` (None or 0: none) in place of this."""
        return replace(self, limit=limit or None)

    def actuator_interval(self, previous: float) -> tuple[float, float]:
        """The commands the actuator applies unchanged after ``previous``."""
        lo, hi = -np.inf, np.inf
        if self.magnitude is not None:
            lo, hi = -self.magnitude, self.magnitude
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
