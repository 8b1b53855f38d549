"""The scene section ``events``: changes of the structure while a run goes on (README "Scenes",
docs/closed-loop.md "Structure events").

Each entry is a time and the changes made then: one floor's mass (a new mass, or a factor on the
scene's), a stiffness factor per story, the damping section's coefficients, the pendulum's mass.
Factors are relative to the scene's own structure (the one the run starts with), so two events
with the same factor do not compound. The structure after an event is the scene's with every
change of the events up to it, a later event overriding the keys it names:
:func:`stillframe.config.scene.changed_scene` writes it as a scene of its own (no events), the
scene a plant of that structure would be built from. The loop applies each event at the first
sample boundary at or after its time (:attr:`stillframe.loop.spec.LoopSpec.events`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from stillframe.config.schema import (
    Floats,
    Floats3,
    Section,
    in_range,
    key,
    magnitude,
    section,
)
from stillframe.errors import InputError

__all__ = ["FACTOR_RANGE", "MAX_EVENTS", "Event", "EventDamping", "changed_keys", "check_event",
           "damping_changes", "first_sample_at"]

#: the events of one scene at most (the plant prepares the structure of each at load)
MAX_EVENTS = 100
#: a stiffness or mass factor: > 0 (a factor of 0 removes the part, which a model cannot carry)
FACTOR_RANGE = (1e-3, 1e3)

#: the damping keys an event may change, by the scene's ``damping.model``
DAMPING_KEYS = {"rayleigh": ("alpha", "beta"), "modal": ("modal_ratios", "high_mode_ratio"),
                "none": ()}


def first_sample_at(time: float, period: float) -> int:
    """The index of the first sample boundary k · ``period`` at or after ``time``; a time within
    rounding of a boundary (the two are decimal values in a scene) is that boundary."""
    ratio = time / period
    nearest = round(ratio)
    return nearest if abs(ratio - nearest) <= 1e-9 * max(1.0, ratio) else math.ceil(ratio)


@dataclass(frozen=True, kw_only=True)
class EventDamping(Section):
    """events[i].damping: the damping coefficients the event changes (null: unchanged); only
    those of the scene's ``damping.model`` (the model itself stays)."""

    alpha: float | None = key(None, magnitude(1e6), doc="rayleigh: new alpha [1/s]")
    beta: float | None = key(None, magnitude(1.0), doc="rayleigh: new beta [s]")
    modal_ratios: Floats | None = key(None, in_range(0.0, 1.0),
                                      doc="modal: new zeta of the first structural modes [-]")
    high_mode_ratio: float | None = key(None, in_range(0.0, 1.0),
                                        doc="modal: new zeta of the modes above [-]")


@dataclass(frozen=True, kw_only=True)
class Event(Section):
    """events[i]: one change of the structure."""

    time: float = key(doc="[s] from the start; applied at the first sample boundary at or "
                          "after it", check=in_range(0.0, 1e6))
    floor: int | None = key(None, in_range(1, 3), doc="the floor whose mass changes")
    mass: float | None = key(None, in_range(1e-6, 1e7), doc="that floor's new mass [kg]")
    mass_factor: float | None = key(None, in_range(*FACTOR_RANGE), doc=(
        "that floor's mass times this, relative to rig.floor_masses [-]"))
    story_stiffness: Floats3 | None = key(None, in_range(*FACTOR_RANGE), doc=(
        "stories 1..3: bending stiffness EJ of the story's blades times this, relative to the "
        "scene's (rig.columns.stiffness_factors) [-]"))
    damping: EventDamping = section(EventDamping)
    pendulum_mass: float | None = key(None, in_range(1e-6, 1e6), doc=(
        "m4 [kg]: mass added at (or taken from) the pendulum's centre of mass, its inertia "
        "about that centre unchanged"))


def damping_changes(event: Event) -> dict[str, Any]:
    """The damping coefficients ``event`` changes, by key."""
    return {f.name: value for f in dataclasses.fields(event.damping)
            if (value := getattr(event.damping, f.name)) is not None}


def changed_keys(event: Event) -> tuple[str, ...]:
    """The scene keys ``event`` changes (dotted; the lists as a whole)."""
    return tuple(k for k, given in (
        ("rig.floor_masses", event.floor is not None),
        ("rig.columns.stiffness_factors", event.story_stiffness is not None),
        *((f"damping.{k}", True) for k in damping_changes(event)),
        ("rig.pendulum.mass", event.pendulum_mass is not None)) if given)


def check_event(name: str, event: Event, damping_model: str) -> None:
    """The checks of one entry (``name`` = ``events[i]``) given the scene's ``damping.model``;
    InputError naming the key."""
    given = (event.mass is not None) + (event.mass_factor is not None)
    if event.floor is None and given:
        which = "mass" if event.mass is not None else "mass_factor"
        raise InputError(f"{name}.{which}: needs floor, the floor whose mass changes")
    if event.floor is not None and given != 1:
        raise InputError(f"{name}.floor: give one of mass (the new mass) and mass_factor, "
                         f"got {'both' if given else 'neither'}")
    allowed = DAMPING_KEYS[damping_model]
    for damping_key in damping_changes(event):
        if damping_key not in allowed:
            have = ", ".join(allowed) or "no coefficients"
            raise InputError(
                f"{name}.damping.{damping_key}: the scene's damping.model is {damping_model}, "
                f"which has {have}; an event changes the coefficients of the scene's damping "
                "model, not the model")
    if not changed_keys(event):
        raise InputError(f"{name}: changes nothing (give floor with mass or mass_factor, "
                         "story_stiffness, damping or pendulum_mass)")
