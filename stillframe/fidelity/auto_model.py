"""``model.type: auto``: the cheapest model, integrator and step that meet a band and tolerance.

The choice rests on measured work-precision data (:mod:`stillframe.fidelity.work_precision`,
shipped as ``stillframe/data/fidelity_table.json`` by ``stillframe bench fidelity --write-table``):

1. the canonical scenes whose frequency content lies inside the requested band count;
2. a run (model, method, dt) qualifies if its worst error on those scenes is within the
   tolerance;
3. its model must also reproduce every mode of the converged reference (FE, 40 elements per
   column) inside the band within the tolerance — checked on the scene's own rig;
4. with ``model.energy_tolerance`` (energy consistency asked for), its measured discrete
   energy-balance error must be within it: only the port-Hamiltonian runs keep (and measure) a
   discrete power balance, so such a scene gets a pH model, and the reason says so (without
   it, pH runs are not candidates: the tools that need a FrameModel could not take them);
5. the qualifying run with the least CPU time per simulated second wins.
"""

from __future__ import annotations

import copy
import datetime
import json
import logging
import platform
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lazy_loader as lazy
import numpy as np
import scipy.linalg as sla

from stillframe.config.scene import Scene, apply_overrides, scene_from_dict
from stillframe.dynamics.models import build_model
from stillframe.errors import InputError
from stillframe.files import write_text
from stillframe.locations import DATA_DIR

__all__ = ["Choice", "choose", "energy_note", "load_table", "resolve_model", "write_table"]

#: loaded on first use: they bring the compiled kernels (numba) and scipy.integrate, which only a
#: ``model.type: auto`` scene needs; every loop node resolves its scene through this module. (Their
#: packages load at once, which lazy_loader warns of: both are lazy ``__init__`` files themselves.)
work_precision = lazy.load("stillframe.fidelity.work_precision", suppress_warning=True)
ph_scene = lazy.load("stillframe.dynamics.ph.scene_model", suppress_warning=True)

TABLE = DATA_DIR / "fidelity_table.json"
log = logging.getLogger("stillframe.auto")


def write_table(result: dict, path: Path, argv: list[str]) -> None:
    """The measured sweep reduced to what the chooser needs, with provenance."""
    runs: dict[tuple[str, str, float], dict[str, Any]] = {}
    for p in result["points"]:
        key = (p["model"], p["method"], p["dt"])
        run = runs.setdefault(key, {"model": p["model"],
                                    "overrides": work_precision.MODELS[p["model"]],
                                    "dofs": p["dofs"], "method": p["method"], "dt": p["dt"],
                                    "error": {}, "cpu_per_s": {}, "energy_error": {}})
        run["error"][p["scene"]] = p["error"]
        run["cpu_per_s"][p["scene"]] = p["cpu_per_s"]
        run["energy_error"][p["scene"]] = p.get("energy_error")
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent, check=False).stdout.strip()
    except OSError:
        commit = ""
    import numba

    table = {
        "provenance": {
            "command": " ".join(["stillframe", *argv[1:]]),
            "created_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "git_commit": commit or "unknown",
            "machine": f"{platform.machine()} {platform.processor()}".strip(),
            "python": platform.python_version(), "numpy": np.__version__,
            "numba": numba.__version__,
            "reference": result["reference"],
            "duration_s": result["duration_s"],
            "error": "max over x1..x3, phi of max_t |y - y_ref| / max_t |y_ref|, 10 ms grid",
            "cost": "CPU seconds (time.process_time) per simulated second, compiled kernels",
            "energy_error": "largest |dH - h(y.u - z.Rz)| of a step over the largest H of the run "
                            "(pH runs: discrete power balance); null: no discrete balance",
        },
        "scene_bands_hz": {k: list(v) for k, v in work_precision.SCENE_BANDS_HZ.items()},
        "runs": list(runs.values()),
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(table, indent=1) + "\n", what="fidelity table")


def load_table(path: Path = TABLE) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"model.type: auto needs the fidelity table {path} ({exc}); "
                         "regenerate it with stillframe bench fidelity --write-table") from None


@dataclass(frozen=True)
class Choice:
    overrides: list[str]  # model.* and integrator.* settings
    model: str
    method: str
    dt: float
    reason: str


def _frequencies(scene_data: dict, overrides: list[str]) -> np.ndarray | None:
    """Undamped frequencies [Hz] of a candidate model on the scene's rig; None if the scene's
    damping is not valid for it (e.g. Rayleigh with beta < 0 on an FE model)."""
    data = {k: v for k, v in scene_data.items() if k not in ("model", "integrator")}
    try:
        scene = scene_from_dict(data, list(overrides))
        if scene.model.type == "ph":
            return np.asarray(ph_scene.modal_table(scene)["frequencies_hz"])
        lin = build_model(scene).linearized()
    except InputError:
        return None
    return np.sqrt(np.clip(sla.eigh(lin.stiffness, lin.mass, eigvals_only=True), 0, None)) \
        / (2 * np.pi)


def _band_mismatch(freqs: np.ndarray, ref: np.ndarray, band: list[float]) -> float:
    """Worst relative frequency error over the reference modes inside the band."""
    inside = ref[(ref >= band[0]) & (ref <= band[1])]
    if inside.size == 0:
        return 0.0
    return float(max(np.min(np.abs(freqs - f)) / f for f in inside))


def _energy_error(run: dict, scenes: list[str]) -> float | None:
    """The run's worst measured energy-balance error on ``scenes`` (None: it keeps none)."""
    errors = [run.get("energy_error", {}).get(s) for s in scenes]
    return None if any(e is None for e in errors) else max(errors)


def choose(scene_data: dict, band: list[float], tolerance: float,
           table: dict | None = None, energy_tolerance: float | None = None) -> Choice:
    """The cheapest measured (model, method, dt) meeting ``band`` [Hz] and ``tolerance`` (and
    ``energy_tolerance`` on the discrete energy-balance error, when given)."""
    table = table or load_table()
    bands = table["scene_bands_hz"]
    scenes = [s for s, (_, hi) in bands.items() if hi <= band[1]] or list(bands)
    reference = work_precision.MODELS[f"fe{work_precision.REFERENCE_MODEL[1]}"]
    ref = _frequencies(scene_data, reference)
    if ref is None:
        ref = _frequencies({**scene_data, "damping": {"model": "modal"}}, reference)
    freqs: dict[str, np.ndarray | None] = {}
    qualified, rejected = [], []
    for run in table["runs"]:
        if energy_tolerance is None and "model.type=ph" in run["overrides"]:
            continue    # the pHDAE is no FrameModel: chosen only when energy consistency is asked
        errors = [run["error"].get(s) for s in scenes]
        if any(e is None for e in errors):
            continue
        error = max(errors)
        cost = max(run["cpu_per_s"][s] for s in scenes)
        if error > tolerance:
            rejected.append((cost, run, f"error {error:.2g} > {tolerance:g}"))
            continue
        energy = _energy_error(run, scenes)
        if energy_tolerance is not None and (energy is None or energy > energy_tolerance):
            rejected.append((cost, run, "no discrete energy balance (the scheme keeps none)"
                             if energy is None else
                             f"energy-balance error {energy:.2g} > {energy_tolerance:g}"))
            continue
        name = run["model"]
        if name not in freqs:
            freqs[name] = _frequencies(scene_data, run["overrides"])
        if freqs[name] is None:
            rejected.append((cost, run, "the scene's damping is invalid for it"))
            continue
        mismatch = _band_mismatch(freqs[name], ref, band)
        if mismatch > tolerance:
            rejected.append((cost, run, f"a mode in the band is off by {mismatch:.2g}"))
            continue
        qualified.append((cost, error, mismatch, run))
    if not qualified:
        raise InputError(
            f"model.tolerance: no measured model, integrator and step meets {tolerance:g} over "
            f"{band[0]:g}-{band[1]:g} Hz (scenes {', '.join(scenes)}); loosen model.tolerance, "
            "narrow model.band_hz, or set damping.model: modal if the damping excludes FE models"
            + ("; only pH runs keep a discrete energy balance (model.energy_tolerance)"
               if energy_tolerance is not None else ""))
    cost, error, mismatch, run = min(qualified, key=lambda q: q[0])
    cheaper = sorted((r for r in rejected if r[0] < cost), key=lambda r: r[0])[:1]
    # with energy consistency asked, also the cheapest run that would have met the rest
    cheaper += sorted((r for r in rejected if r[0] < cost and "energy" in r[2]
                       and r not in cheaper), key=lambda r: r[0])[:1]
    why_not = "".join(f"; cheaper {r[1]['model']} {r[1]['method']} dt={r[1]['dt']:g} rejected: "
                      f"{r[2]}" for r in cheaper)
    reason = (f"{run['model']} ({run['dofs']} DOFs) {run['method']} dt={run['dt']:g} s: cheapest "
              f"of {len(qualified)} measured choices meeting {tolerance:g} over {band[0]:g}-"
              f"{band[1]:g} Hz on scenes {', '.join(scenes)} (worst error {error:.2g}, modes in "
              f"band within {mismatch:.2g}, {cost:.2g} CPU s per simulated s"
              f"{energy_note(run, scenes, energy_tolerance)}){why_not}")
    overrides = [*run["overrides"], f"integrator.method={run['method']}",
                 f"integrator.dt={run['dt']!r}"]
    log.info("model.type auto: %s", reason)
    return Choice(overrides, run["model"], run["method"], run["dt"], reason)


def energy_note(run: dict, scenes: list[str], energy_tolerance: float | None) -> str:
    """The reason's clause on energy consistency, when the scene asks for it."""
    if energy_tolerance is None:
        return ""
    return (f"; energy consistency asked (model.energy_tolerance {energy_tolerance:g}): its "
            f"discrete power balance holds to {_energy_error(run, scenes):.2g} of H per step, "
            "which only the port-Hamiltonian AVF midpoint runs keep")


def resolve_model(scene: Scene) -> tuple[Scene, Choice | None]:
    """The step after loading: a scene with ``model.type: auto`` becomes the scene with the chosen
    model, integrator and step (and the choice, with its reason); any other scene is returned
    unchanged with None."""
    if scene.model.type != "auto":
        return scene, None
    band = scene.model.band_hz
    if band[0] >= band[1]:
        raise InputError(
            f"model.band_hz: the lower edge must be below the upper (got {list(band)})")
    data = scene.to_dict()
    choice = choose(copy.deepcopy(data), list(band), scene.model.tolerance,
                    energy_tolerance=scene.model.energy_tolerance)
    apply_overrides(data, choice.overrides)
    return scene_from_dict(data), choice
