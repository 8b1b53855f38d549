"""What the loop's processes agree on for a scene: the design model they build, the topics the
estimator reads and the command topic (docs/nodes.md). The one-process loop and the three nodes
take these from here, so that they cannot disagree."""

from __future__ import annotations

from stillframe.config.scene import changed_scene
from stillframe.config.schema import Section
from stillframe.contract import topics
from stillframe.contract.codecs import COMMAND_TOPICS, SENSOR_TOPICS
from stillframe.contract.signals import FORCE, actuator_of
from stillframe.design.identified import frame_for
from stillframe.dynamics.models.frame import FrameModel


def design_model(scene: Section) -> FrameModel:
    """The model the estimator and the controller are designed on (``design.model``, on the
    structure after ``design.after_events`` of the scene's events)."""
    after = scene.design.after_events
    return frame_for(scene.design.model, scene.design.file,
                     changed_scene(scene, after) if after else scene, "design.file")


def estimator_inputs(scene: Section) -> tuple[topics.TopicSpec, ...]:
    """The topics the estimator reads (none without one): the five sensors, the floor-3 actuator's
    load cell when the controller drives that force (the force applied), and ``state_truth`` for
    the ``truth`` estimator."""
    if scene.estimator.type == "none":
        return ()
    extra = [topics.FLOOR3_LOAD_CELL] if actuator_of(scene) == FORCE else []
    if scene.estimator.type == "truth":
        extra.append(topics.STATE_TRUTH)
    return (*SENSOR_TOPICS, *extra)


def command_topic(scene: Section) -> topics.TopicSpec | None:
    """The topic the scene's controller commands on (None without a controller)."""
    active = actuator_of(scene)
    return None if active is None else COMMAND_TOPICS[active]
