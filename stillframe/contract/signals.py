"""What flows around the loop, one sample period at a time (docs/architecture.md, topic contract).

Plain data, no middleware: the simulator makes a :class:`Sample`, the estimator turns it into
an :class:`Estimate`, the controller answers with a :class:`Command` stamped like the estimate.
Physical state order: [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from stillframe.config.scene import Scene

__all__ = ["ACTUATOR", "Command", "Estimate", "Sample", "actuator_of", "full_inputs"]


@dataclass
class Sample:
    """Sensor readings at time ``t``: ``measurements`` = [a1, a2, a3, φ] (accelerometers and
    encoder), ``force`` = the load cell on the excited floor; ``present`` marks the channels that
    arrived (a node assembling messages leaves the others False). ``truth`` is the simulator's
    physical state, for evaluation and the ``truth`` estimator, never for a filter. ``applied``
    is the [torque, force] the actuators applied over the previous period (after saturation and
    slew limits), as the simulator reports it (NaN where not received)."""

    t: float
    measurements: np.ndarray
    force: float
    present: np.ndarray = field(default_factory=lambda: np.ones(5, dtype=bool))
    truth: np.ndarray | None = None
    applied: np.ndarray | None = None


@dataclass
class Estimate:
    """State estimate at ``t``: ``z`` in the design model's coordinates [q, q̇], ``physical``
    the 8 physical components, ``covariance`` their 8×8 covariance (None when exact);
    ``applied`` the [torque, force] the estimator took as applied over the period before ``t``
    (the simulator's report, or its stand-in where that was lost; None: not known)."""

    t: float
    z: np.ndarray
    physical: np.ndarray
    covariance: np.ndarray | None = None
    applied: np.ndarray | None = None


@dataclass
class Command:
    """Actuator commands computed from the estimate stamped ``t``: pendulum torque [N m] and
    floor-3 force [N], with the controller's flags for ``/diagnostics``."""

    t: float
    torque: float = 0.0
    force: float = 0.0
    enabled: bool = False
    saturated: bool = False
    singular: bool = False
    watchdog: bool = False
    runaway: bool = False

    @property
    def vector(self) -> np.ndarray:
        """[torque, floor-3 force], the order of :class:`stillframe.plant.frame_plant.FramePlant`
        inputs."""
        return np.array([self.torque, self.force])


#: the actuators, as indices into :attr:`Command.vector`: the pendulum torque, the floor-3 force
TORQUE, FORCE = 0, 1
#: The actuator each controller type drives.
ACTUATOR = {"lqg": TORQUE, "euk_pendulum": TORQUE, "euk_floor": FORCE, "passivity": TORQUE,
            "mpc": TORQUE}


def actuator_of(scene: Scene) -> int | None:
    """The index in [torque, floor-3 force] the scene's controller drives (None: no controller)."""
    return ACTUATOR.get(scene.controller.type)


def full_inputs(control: np.ndarray, force: float, excited_floor: int) -> np.ndarray:
    """u = [f1, f2, f3, torque] (eq. 5.56) from [torque, floor-3 force] and the excitation."""
    u = np.zeros(4)
    u[excited_floor - 1] = force
    u[2] += control[1]
    u[3] = control[0]
    return u
