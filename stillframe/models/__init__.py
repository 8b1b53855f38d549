"""Dynamic models of the rig; :func:`build_model` makes the one a scene asks for."""

from __future__ import annotations

from stillframe.models.damping import damping_matrix
from stillframe.models.frame import INPUT_NAMES, FrameModel, LinearModel
from stillframe.models.structure import (
    Structure,
    craig_bampton,
    fe_structure,
    lumped_structure,
)
from stillframe.schema import Section

__all__ = ["INPUT_NAMES", "FrameModel", "LinearModel", "build_model", "build_structure"]


def build_structure(scene: Section) -> Structure:
    """The scene's undamped structure: lumped, FE or Craig–Bampton-reduced FE."""
    model = scene.model
    if model.type == "lumped":
        return lumped_structure(scene.rig)
    full = fe_structure(scene.rig, model.elements_per_column)
    if model.type == "fe":
        return full
    return craig_bampton(full, model.modes)


def build_model(scene: Section) -> FrameModel:
    """Structure + damping + pendulum, as the scene's ``model`` and ``damping`` sections say."""
    structure = build_structure(scene)
    return FrameModel(structure.with_damping(damping_matrix(structure, scene.damping)), scene.rig)
