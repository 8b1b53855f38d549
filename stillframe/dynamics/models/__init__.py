"""Dynamic models of the rig; :func:`build_model` makes the one a scene asks for."""

from __future__ import annotations

import numpy as np

from stillframe.config.scene import Scene
from stillframe.dynamics.models.damping import damping_parts
from stillframe.dynamics.models.frame import INPUT_NAMES, FrameModel, LinearModel
from stillframe.dynamics.models.structure import (
    Structure,
    craig_bampton,
    fe_structure,
    lumped_structure,
)
from stillframe.errors import InputError

__all__ = ["INPUT_NAMES", "FrameModel", "LinearModel", "build_model", "build_structure"]


def build_structure(scene: Scene) -> Structure:
    """The scene's undamped structure: lumped, FE or Craig–Bampton-reduced FE."""
    model = scene.model
    if model.type == "ph":
        raise InputError("model.type: ph is a port-Hamiltonian DAE, not a FrameModel: modes, "
                         "simulate and the plant of closed-loop/launch take it; a design model "
                         "or this tool needs lumped, fe or modal (design.model: lumped or file)")
    if model.type == "lumped":
        return lumped_structure(scene.rig)
    full = fe_structure(scene.rig, model.elements_per_column)
    if model.type == "fe":
        return full
    return craig_bampton(full, model.modes)


MAX_MASS_CONDITION = 1e12


def build_model(scene: Scene) -> FrameModel:
    """Structure + damping + pendulum, as the scene's ``model`` and ``damping`` sections say."""
    structure = build_structure(scene)
    condition = np.linalg.cond(structure.mass)
    if condition > MAX_MASS_CONDITION:
        raise InputError(
            f"rig.columns.density: {scene.rig.columns.density:g} leaves the {structure.name} "
            f"mass matrix singular or nearly so (condition number {condition:.2g}); use "
            "model.type: lumped for massless columns, or a larger density"
        )
    return FrameModel(structure.with_damping(damping_parts(structure, scene.damping)), scene.rig)
