"""The structure identified from a closed loop's own records
(:mod:`stillframe.identification.loop_structure`): the torque-late realization and four-DOF MKR
give back the rig's linear matrices exactly, and the loop's probed records of a changed
structure give its frequencies within 1 % of the true changed model's (the roots of
det(K − ω² M) of the matrices assembled independently,
:func:`tests.support.scenes.characteristic_frequencies`); without the probe they do not."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stillframe.config.scene import changed_scene
from stillframe.design.discrete import first_order_hold
from stillframe.design.identified import storeys_frame
from stillframe.dynamics.models import build_model
from stillframe.dynamics.models.structure import Structure
from stillframe.errors import StillframeError
from stillframe.identification.loop_structure import (
    ACTUATOR_DOFS,
    SENSOR_DOFS,
    identify_loop_modes,
    identify_loop_structure,
    torque_recorded_late,
)
from stillframe.identification.mkr import mkr
from stillframe.loop.designs import design_frequencies
from tests.support.loop_records import loop_records
from tests.support.scenes import characteristic_frequencies, thesis_scene


def test_the_torque_recorded_late_and_mkr_on_four_dofs_give_the_rigs_matrices() -> None:
    """The sampled linear rig (ZOH at 32 Hz) written as the records see it, (A, [A⁻¹ B_f, B_τ],
    C A): :func:`torque_recorded_late` and MKR with the accelerometers on DOFs 0-2, the force on
    0 and the torque on φ return M, K, R of the linearised model to rounding."""
    scene = thesis_scene("change_mass_floor2")
    linear = build_model(scene).linearized()
    a_c, b_c = linear.state_space()
    b_c = b_c[:, [0, 3]]
    d = first_order_hold(a_c, b_c, 1 / 32)
    A, B, C = d.phi, d.gamma0, a_c[4:7]
    recorded = np.column_stack([np.linalg.solve(A, B[:, 0]), B[:, 1]])
    found = mkr(A, torque_recorded_late(A, recorded), C @ A, 1 / 32, SENSOR_DOFS, ACTUATOR_DOFS)
    for got, want in ((found.M, linear.mass), (found.K, linear.stiffness),
                      (found.R, linear.damping)):
        np.testing.assert_allclose(got, want, atol=1e-9 * np.max(np.abs(want)))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["change_mass_floor2", "change_stiffness_story1"])
def test_probed_closed_loop_records_identify_the_changed_structure(name: str) -> None:
    """The scene's loop with the adaptation's probe (0.003 N m) on the structure after its
    event from the start; 30 s of records from 5 s after the control starts: the identified
    frequencies and those of the design model MKR rebuilds lie within 1 % of the true ones
    (measured: 0.3 %); its storeys' mass and stiffness within 5 % of the rig's entry by entry
    (the largest)."""
    changed = changed_scene(thesis_scene(name), 1)
    scene = dataclasses.replace(
        thesis_scene(name, ["adaptation.enabled=true", "duration=45", "evaluation.window=5",
                                "events=[]"]),
        rig=changed.rig, events=())
    t, u, y = loop_records(scene)
    window = (t >= 15) & (t < 45)
    found = identify_loop_structure(u[window], y[window], 1 / 32, scene.rig)
    truth = characteristic_frequencies(scene)
    np.testing.assert_allclose(np.sort(found.ident.modes.frequency_hz), truth, rtol=0.01)
    s = found.structure
    design = storeys_frame(Structure("x", s.M, s.K, (0, 1, 2), ("x1", "x2", "x3"), s.R),
                           scene.rig)
    np.testing.assert_allclose(design_frequencies(design), truth, rtol=0.01)
    true_structure = build_model(scene).structure
    for got, want in ((s.M, true_structure.mass), (s.K, true_structure.stiffness)):
        assert np.max(np.abs(got - want)) < 0.05 * np.max(np.abs(want))


@pytest.mark.slow
def test_without_the_probe_the_closed_loop_records_do_not_identify_the_plant() -> None:
    """The same loop without a probe: the torque is a linear function of past outputs and the
    direct identification is ill-posed: each of six 10 s windows is refused (OKID's Markov
    parameters diverge) or misses a true frequency by more than 5 % (measured: all six
    refused)."""
    scene = thesis_scene("change_mass_floor2", [
        "adaptation.enabled=true", "adaptation.probe_std=0", "duration=70",
        "evaluation.window=5", "events=[]"])
    t, u, y = loop_records(scene)
    truth = characteristic_frequencies(scene)
    failed = 0
    for start in range(10, 70, 10):
        window = (t >= start) & (t < start + 10)
        try:
            f = np.sort(identify_loop_modes(u[window], y[window], 1 / 32).modes.frequency_hz)
        except StillframeError:
            failed += 1
            continue
        failed += f.size != truth.size or bool(np.any(np.abs(f / truth - 1) > 0.05))
    assert failed == 6
