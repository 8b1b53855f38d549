"""model.type: auto against the shipped measured table and the models' own frequencies."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from stillframe.config.scene import scene_from_dict
from stillframe.dynamics.models import build_model
from stillframe.errors import InputError
from stillframe.fidelity.auto_model import resolve_model

MODAL = ["damping.model=modal", "model.type=auto"]


def test_a_0_to_15_hz_band_at_1_percent_picks_a_reduced_model() -> None:
    scene, choice = resolve_model(scene_from_dict(
        {"name": "t"}, [*MODAL, "model.band_hz=[0, 15]", "model.tolerance=0.01"]))
    model = build_model(scene)
    assert model.n_dof <= 4  # floors + pendulum only (fe1: columns' mass, no inner nodes)
    assert choice.model == "fe1"
    assert "worst_case, swing" in choice.reason
    # the lumped model is cheaper but its second mode is 3.8 % off the converged FE mesh
    lumped = build_model(scene_from_dict({"name": "t"}, ["damping.model=modal"])).linearized()
    f = np.sqrt(sla.eigh(lumped.stiffness, lumped.mass, eigvals_only=True)) / (2 * np.pi)
    assert f[1] / 1.91144873 - 1 > 0.01


def test_a_0_to_200_hz_band_at_a_tight_tolerance_picks_the_fine_fe_mesh() -> None:
    """Only models built on the 40-element mesh keep the column modes to 1e-5; the measured
    data make its Craig–Bampton reduction cheaper than the full mesh."""
    scene, _ = resolve_model(scene_from_dict({"name": "t"}, [*MODAL, "model.band_hz=[0, 200]",
                                                             "model.tolerance=1e-5"]))
    assert scene.model.type in ("fe", "modal") and scene.model.elements_per_column == 40
    model = build_model(scene)
    full = build_model(scene_from_dict({"name": "t"}, ["damping.model=modal", "model.type=fe",
                                                       "model.elements_per_column=40"]))
    ref = np.sqrt(sla.eigh(full.linearized().stiffness, full.linearized().mass,
                           eigvals_only=True)) / (2 * np.pi)
    lin = model.linearized()
    got = np.sqrt(sla.eigh(lin.stiffness, lin.mass, eigvals_only=True)) / (2 * np.pi)
    inside = ref[ref <= 200]
    assert inside.size == 8  # 4 floor/pendulum modes + 4 column modes
    np.testing.assert_allclose(got[:8], inside, rtol=1e-5)


def test_impossible_requests_fail_clearly() -> None:
    with pytest.raises(InputError, match=r"model\.tolerance: no measured model"):
        resolve_model(scene_from_dict({"name": "t"}, [*MODAL, "model.band_hz=[0, 200]",
                                                      "model.tolerance=1e-8"]))
    with pytest.raises(InputError, match=r"model\.band_hz: the lower edge must be below"):
        resolve_model(scene_from_dict({"name": "t"}, [*MODAL, "model.band_hz=[20, 10]"]))


def test_energy_consistency_asked_picks_the_ph_model_and_says_why() -> None:
    """With model.energy_tolerance only runs that keep a discrete power balance qualify: the
    measured pH rows (balance error ~1e-14 of H), cheapest first; the reason names the energy
    criterion and the cheaper FrameModel run it rejected for having no balance."""
    scene, choice = resolve_model(scene_from_dict(
        {"name": "t"}, [*MODAL, "model.band_hz=[0, 15]", "model.tolerance=0.01",
                        "model.energy_tolerance=1e-12"]))
    assert scene.model.type == "ph" and choice.model.startswith("ph")
    assert "energy consistency asked (model.energy_tolerance 1e-12)" in choice.reason
    assert "no discrete energy balance" in choice.reason
    # the same request without the energy tolerance: a FrameModel (pH is not a candidate)
    _, plain = resolve_model(scene_from_dict(
        {"name": "t"}, [*MODAL, "model.band_hz=[0, 15]", "model.tolerance=0.01"]))
    assert not plain.model.startswith("ph")
    with pytest.raises(InputError, match=r"only pH runs keep a discrete energy balance"):
        resolve_model(scene_from_dict({"name": "t"}, [
            *MODAL, "model.band_hz=[0, 15]", "model.tolerance=0.01",
            "model.energy_tolerance=1e-16"]))
