"""Identified structures (MKR mass, stiffness, damping) as a :class:`Structure` carrying the
pendulum, so that the thesis's LQG design model and plant (eq. 5.199–5.207) are a
:class:`~stillframe.dynamics.models.frame.FrameModel` like the lumped and FE ones.

Two file kinds:

- YAML ``format: stillframe-mkr`` with ``mass``, ``stiffness``, ``damping`` (3×3, floors 1–3)
  and ``source`` (provenance); the thesis's matrices are bundled as ``thesis_mkr``.
- ``.npz`` identified-model files (``format: stillframe-identified-model``, written by
  ``stillframe identify --save-model``) holding the optional MKR arrays ``M``, ``K``, ``R``.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import yaml

from stillframe.config.scene import Rig, Scene
from stillframe.config.schema import show
from stillframe.config.yamlio import MAX_YAML_BYTES, load_yaml, problem
from stillframe.contract.model_file import STRUCTURE, check_structure, read_archive
from stillframe.dynamics.models import build_model
from stillframe.dynamics.models.frame import FrameModel
from stillframe.dynamics.models.structure import Structure
from stillframe.errors import InputError
from stillframe.files import read_bytes, write_text
from stillframe.locations import DATA_DIR

__all__ = ["frame_for", "identified_frame", "load_identified_structure", "resolve_model_file"]


def resolve_model_file(name: str, key: str) -> Path:
    """A bundled model name (``thesis_mkr``) or a path to a ``.yaml``/``.npz`` file."""
    bundled = DATA_DIR / f"{name}.yaml"
    if "/" not in name and "." not in name and bundled.exists():
        return bundled
    path = Path(name)
    if not path.exists():       # a FIFO or a directory is named as such by the reader
        known = ", ".join(sorted(p.stem for p in DATA_DIR.glob("*.yaml")))
        raise InputError(f"{key}: {name!r} is neither a file nor a bundled model ({known})")
    return path


#: the YAML format's names of the structure's matrices (the .npz format's are M, K, R)
YAML_NAMES = {"M": "mass", "K": "stiffness", "R": "damping"}


def _matrices_from_yaml(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str], str]:
    raw = read_bytes(path, what="model file", max_bytes=MAX_YAML_BYTES)
    try:
        data = load_yaml(raw)
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not a model file: not valid YAML: {problem(exc)}") from None
    if not isinstance(data, dict) or data.get("format") != "stillframe-mkr":
        raise InputError(f"{path}: not a model file (expected 'format: stillframe-mkr')")
    arrays = {}
    for key, name in YAML_NAMES.items():
        if name not in data:
            raise InputError(f"{path}: missing {name}")
        try:
            arrays[key] = np.asarray(data[name], dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{path}: {name!r} must be a numeric matrix, got "
                             f"{show(data[name])}") from None
    return arrays, YAML_NAMES, str(data.get("source", path.name))


def _matrices_from_npz(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str], str]:
    archive = read_archive(path)
    if not archive.has_mkr:
        raise InputError(f"{path}: the identified model holds no MKR matrices M, K, R")
    arrays = {key: archive.arrays[key] for key in STRUCTURE}
    return arrays, {key: key for key in STRUCTURE}, json.dumps(archive.meta["provenance"])


def load_identified_structure(path: Path) -> Structure:
    """The identified floors-only structure with its damping: 3x3 matrices that pass the
    model file's physical checks (:func:`~stillframe.contract.model_file.check_structure`);
    InputError naming the file and the entry otherwise."""
    reader = _matrices_from_npz if path.suffix == ".npz" else _matrices_from_yaml
    arrays, labels, source = reader(path)
    for key, matrix in arrays.items():
        if matrix.shape != (3, 3):
            raise InputError(f"{path}: {labels[key]!r} must be a 3x3 matrix (floors 1-3), got "
                             f"shape {matrix.shape}")
    check_structure(arrays, str(path), labels)
    return storeys(arrays["M"], arrays["K"], arrays["R"], source)


def identified_frame(name: str, rig: Rig, key: str) -> FrameModel:
    """Identified structure + the rig's nonlinear pendulum on floor 3 (eq. 5.200–5.205)."""
    return storeys_frame(load_identified_structure(resolve_model_file(name, key)), rig)


def storeys_frame(structure: Structure, rig: Rig) -> FrameModel:
    """An identified floors-only ``structure`` with the rig's pendulum: the design model."""
    model = FrameModel(structure, rig)
    model.name = "identified"
    return model


def storeys(mass: np.ndarray, stiffness: np.ndarray, damping: np.ndarray,
            source: str) -> Structure:
    """The floors-only structure of M, K, R (3×3, floors 1–3), named after its ``source``."""
    return Structure(f"identified({source})", mass, stiffness, (0, 1, 2), ("x1", "x2", "x3"),
                     damping)


def write_mkr_file(path: Path, structure: Structure, source: str) -> None:
    """``structure`` as a model file ``format: stillframe-mkr`` (what ``design.model: file`` and
    the nodes' ``design`` parameter read; floats written to the last bit)."""
    data = {"format": "stillframe-mkr", "source": source,
            **{name: np.asarray(matrix, dtype=float).tolist() for name, matrix in (
                ("mass", structure.mass), ("stiffness", structure.stiffness),
                ("damping", structure.damping))}}
    write_text(path, yaml.safe_dump(data, sort_keys=False), what="model file")


def frame_for(source: str, file: str, scene: Scene, key: str) -> FrameModel:
    """The scene's own model (``scene``), the lumped model of the scene's rig and damping
    (``lumped``), or the identified one of ``file`` (``file``)."""
    if source == "file":
        return identified_frame(file, scene.rig, key)
    if source == "lumped" and scene.model.type != "lumped":
        scene = dataclasses.replace(scene, model=dataclasses.replace(scene.model, type="lumped"))
    return build_model(scene)
