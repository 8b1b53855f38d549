"""The identified-model file: round trip, and a clear refusal of every kind of bad file."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from stillframe.errors import InputError
from stillframe.identification.mkr import mkr
from stillframe.identification.model_file import load_model, model_from_identification, save_model
from stillframe.identification.pipeline import identify
from tests.support.ident_systems import DAMPING, MASS, STIFFNESS, continuous, discrete, simulate

DT = 0.02


@pytest.fixture(scope="module")
def model():
    b2 = np.array([[1.0], [0.0], [0.0]])
    A, B, C, D = discrete(*continuous(MASS, STIFFNESS, DAMPING, b2, "acceleration"), DT)
    u = np.random.default_rng(0).standard_normal((600, 1))
    ident = identify(u, simulate(A, B, C, D, u), DT, "okid-era", 6, observer_order=3)
    physical = mkr(ident.A, ident.B, ident.C, DT, [0, 1, 2], [0])
    return model_from_identification(
        ident, ["excitation/wrench:force.x"], [f"floor{i}/imu:linear_acceleration.x"
                                               for i in (1, 2, 3)],
        provenance={"bag": "hammer_floor1", "topics": ["/frame/floor1/imu"]}, physical=physical,
        extra={"rayleigh": {"alpha": 0.9751, "beta": -2.8815e-4}},
    )


def test_round_trip_keeps_every_field(tmp_path, model):
    path = tmp_path / "model.npz"
    save_model(path, model)
    back = load_model(path)
    for key in ("A", "B", "C", "D", "G"):
        assert np.array_equal(getattr(back, key), getattr(model, key))
    for key in ("M", "K", "R"):
        assert np.array_equal(getattr(back.physical, key), getattr(model.physical, key))
    for key in ("frequency_hz", "damping_ratio", "eigenvalues", "shapes"):
        assert np.array_equal(getattr(back.modes, key), getattr(model.modes, key))
    assert back.dt == DT
    assert back.inputs == model.inputs and back.outputs == model.outputs
    assert back.provenance == {**model.provenance}
    assert back.provenance["method"] == "okid-era" and back.provenance["order"] == 6
    assert back.extra == {"rayleigh": {"alpha": 0.9751, "beta": -2.8815e-4}}


def rewrite(path, **changes):
    """Copy a saved model file with some arrays replaced (None deletes)."""
    with np.load(path, allow_pickle=False) as archive:
        data = {k: archive[k] for k in archive.files}
    for key, value in changes.items():
        if value is None:
            data.pop(key)
        else:
            data[key] = value
    np.savez(path, **data)


@pytest.mark.parametrize(("change", "message"), [
    ({"G": None, "A": None}, "missing arrays \\['A'\\]"),
    ({"B": np.ones((5, 1))}, "'B' has shape \\(5, 1\\)"),
    ({"C": np.full((3, 6), np.nan)}, "'C' contains NaN"),
    ({"K": None}, "M, K and R must be given together"),
    ({"extra_matrix": np.eye(2)}, "unknown arrays"),
    ({"meta": np.array("{not json")}, "not valid JSON"),
    ({"mode_frequency_hz": np.array([3.0, 2.0, 1.0])}, "ascending"),
])
def test_bad_files_are_refused(tmp_path, model, change, message):
    path = tmp_path / "model.npz"
    save_model(path, model)
    rewrite(path, **change)
    with pytest.raises(InputError, match=message):
        load_model(path)


@pytest.mark.parametrize(("meta_change", "message"), [
    ({"format": "something"}, "meta.format"),
    ({"version": 99}, "version 99"),
    ({"dt": -1.0}, "meta.dt"),
    ({"outputs": ["y"]}, "meta.outputs"),
    ({"provenance": {"method": "okid-era"}}, "provenance"),
])
def test_bad_metadata_is_refused(tmp_path, model, meta_change, message):
    path = tmp_path / "model.npz"
    save_model(path, model)
    with np.load(path, allow_pickle=False) as archive:
        meta = json.loads(str(archive["meta"]))
    rewrite(path, meta=np.array(json.dumps({**meta, **meta_change})))
    with pytest.raises(InputError, match=message):
        load_model(path)


def test_not_a_model_file(tmp_path, model):
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    with pytest.raises(InputError, match=r"not a readable \.npz"):
        load_model(text)
    np.save(tmp_path / "array.npy", np.eye(2))
    with pytest.raises(InputError, match="single array"):
        load_model(tmp_path / "array.npy")
    with pytest.raises(InputError, match="cannot read the model file"):
        load_model(tmp_path / "missing.npz")
    with pytest.raises(InputError, match="'G' has shape"):
        save_model(tmp_path / "bad.npz", replace(model, G=np.ones((2, 2))))
