"""What each process of the loop builds from a scene, in one place: the simulator's spec and
plant, the estimator, the controller.

sim_node, estimator_node, controller_node and the one-process loop build their parts with these
functions, and :func:`check_loop` builds them all at once: ``stillframe launch`` (and what runs
through it: ``demo``, ``experiment``, ``reproduce``) calls it before it starts any process, so a
scene that a node would refuse (an ``integrator.dt`` that does not divide the sample period, a
model file that does not load, a design that cannot be made) is one line and exit code 2 there,
not a node's error after the others started.
"""

from __future__ import annotations

from stillframe.config.scene import Scene
from stillframe.control.factory import make_controller
from stillframe.control.supervisor import Controller
from stillframe.dynamics.models.frame import FrameModel
from stillframe.estimation.factory import Estimator, make_estimator
from stillframe.loop.designs import check_adaptation
from stillframe.loop.spec import LoopSpec
from stillframe.loop.wiring import design_model
from stillframe.plant.frame_plant import make_plant
from stillframe.plant.protocol import Plant

__all__ = ["check_loop", "controller_of", "estimator_of", "simulator_of"]


def simulator_of(scene: Scene, *, mode: str = "lockstep",
                 **spec_options: float) -> tuple[LoopSpec, Plant]:
    """sim_node's spec (:meth:`LoopSpec.of` with ``mode`` and ``spec_options``) and plant."""
    return LoopSpec.of(scene, mode=mode, **spec_options), make_plant(scene)


def estimator_of(scene: Scene, design: FrameModel | None = None) -> Estimator | None:
    """estimator_node's estimator (None for ``estimator.type: none``), on ``design`` (default:
    the scene's design model)."""
    if scene.estimator.type == "none":
        return None
    return make_estimator(scene, design_model(scene) if design is None else design)


def controller_of(scene: Scene, design: FrameModel | None = None) -> Controller | None:
    """controller_node's controller (None for ``controller.type: none``), on ``design``."""
    if scene.controller.type == "none":
        return None
    return make_controller(scene, design_model(scene) if design is None else design)


def check_loop(scene: Scene, *, mode: str = "lockstep") -> None:
    """Build every part the loop's nodes build from ``scene`` in ``mode`` and throw them away:
    InputError (or IntegrationError) with the node's own message where one would refuse it."""
    simulator_of(scene, mode=mode)
    design = (None if scene.estimator.type == scene.controller.type == "none"
              else design_model(scene))
    estimator_of(scene, design)
    controller_of(scene, design)
    check_adaptation(scene, mode=mode)
