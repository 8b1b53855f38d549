"""Axis labels of scene keys, read from the schema's docs (``key(..., doc="m1..m3 [kg]")``)."""

from __future__ import annotations

import pytest

from stillframe.config.labels import NO_UNIT, key_label
from stillframe.errors import InputError


@pytest.mark.parametrize(("key", "label"), [
    ("rig.floor_masses.2", "m2 [kg] (rig.floor_masses.2)"),
    ("rig.columns.lengths.3", "L3 [m] (rig.columns.lengths.3)"),
    ("rig.pendulum.half_length", "L4 [m] (rig.pendulum.half_length)"),
    ("duration", "duration [s] (duration)"),
    ("excitation.amplitudes.2", "harmonics: force amplitudes [N] #2 (excitation.amplitudes.2)"),
    ("rig.columns.per_story", "blades per story [-] (rig.columns.per_story)"),
    ("integrator.dt", "fixed step, or output step of adaptive methods [s] (integrator.dt)"),
])
def test_labels_carry_the_declared_symbol_and_unit(key: str, label: str) -> None:
    assert key_label(key) == label


def test_a_number_without_a_declared_unit_says_so() -> None:
    assert key_label("controller.input_weight").endswith(f"{NO_UNIT} (controller.input_weight)")


@pytest.mark.parametrize("key", ["rig.nope", "rig", "rig.floor_masses.x", "duration.1.2"])
def test_unknown_keys_are_input_errors(key: str) -> None:
    with pytest.raises(InputError):
        key_label(key)
