"""The scene's controller: ``controller.type`` on the design model (scene ``design`` section)."""

from __future__ import annotations

from controller_node.euk import EUKLaw
from controller_node.lqg import LQGLaw, design_lqr
from controller_node.supervisor import Controller
from stillframe.errors import InputError
from stillframe.models import FrameModel
from stillframe.schema import Section

TORQUE_INPUT = 3  # index of the hinge torque in u = [f1, f2, f3, torque]
#: The actuator each controller type drives: 0 pendulum torque, 1 floor-3 force.
ACTUATOR = {"lqg": 0, "euk_pendulum": 0, "euk_floor": 1}


def actuator_of(scene: Section) -> int | None:
    """The index in [torque, floor-3 force] the scene's controller drives (None: no controller)."""
    return ACTUATOR.get(scene.controller.type)


def make_controller(scene: Section, design: FrameModel) -> Controller:
    """The controller of ``scene.controller.type`` (not ``none``)."""
    c = scene.controller
    period = 1.0 / scene.sensors.rate_hz
    floor = scene.excitation.floor
    if c.type == "lqg":
        law = LQGLaw(design_lqr(design, period, c.state_weights, c.input_weight, TORQUE_INPUT,
                                floor), c.feedforward)
    elif c.type in ("euk_pendulum", "euk_floor"):
        variant = "pendulum" if c.type == "euk_pendulum" else "floor"
        law = EUKLaw(design, variant, floor, c.hold_stiffness, c.hold_damping, c.singular_margin)
    else:
        raise InputError(f"controller.type: {c.type!r} computes no command")
    actuators = scene.actuators
    actuator_limit = (actuators.torque_limit, actuators.force_limit)[ACTUATOR[c.type]]
    return Controller(law, ACTUATOR[c.type], period, c.start, c.limit, c.watchdog_periods,
                      actuator_limit)
