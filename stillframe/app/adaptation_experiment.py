"""The adaptation measured against an oracle, through the nodes (docs/adaptation.md): three
lock-step launches of one change scene with its seeds.

- **fixed**: the scene's controller, designed before the change, kept (``adaptation.enabled``
  false);
- **adaptive**: the same with ``adaptation.enabled`` (the probe, the detection, the
  re-identification and the hand-over of :mod:`stillframe.loop.adaptation`);
- **oracle**: the LQG designed on the true model after the scene's events
  (``design.after_events``), from the start, no adaptation.

Each run's reductions are its sim_node's (``evaluation.window`` at the end of the run, against the
same run without control: the scenes' ``baseline: open_loop``). The result's ``adaptation``
holds exactly these keys: ``change_at_s`` (the sample the first event applied at),
``detected_at_s`` (the first detection after it; None without one), ``identified_hz`` (the
design's identified frequencies; None without one), ``true_hz`` (the true changed model's, the
plant's model after the events linearised, its lowest as many modes as the identification has),
``reduction_pct`` with ``fixed``, ``adaptive``, ``oracle``, each ``{"displacement": [3],
"velocity": [3]}``. ``details`` beside it: the hand-over, the design model's frequencies, the
targets and whether each is met, the run directories.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.launcher import LaunchResult, run_scene
from stillframe.config.scene import Scene, changed_scene, load_scene, scene_from_dict
from stillframe.dynamics.models import build_model
from stillframe.errors import InputError
from stillframe.loop.designs import check_adaptation, design_frequencies

RUNS = ("fixed", "adaptive", "oracle")
#: the adaptation's targets: detection delay [s], frequency error [-], adaptive / oracle
#: displacement reduction on every floor [-]
DETECTION_S, FREQUENCY_ERROR, ORACLE_SHARE = 15.0, 0.01, 0.9


def run_overrides(scene: Scene, user: Sequence[str]) -> dict[str, list[str]]:
    """Each run's overrides after the user's."""
    return {"fixed": [*user, "adaptation.enabled=false"],
            "adaptive": [*user, "adaptation.enabled=true"],
            "oracle": [*user, "adaptation.enabled=false",
                       f"design.after_events={len(scene.events)}"]}


def check_experiment(scene: Scene) -> None:
    """What the three runs need (InputError naming the key, before anything starts)."""
    if not scene.events:
        raise InputError("events: the scene changes nothing; adapt compares loops across a "
                         "change of the structure (e.g. scenes/change_mass_floor2.yaml)")
    if scene.design.model == "file":
        raise InputError("design.model: file; the oracle designs on the true model after the "
                         "events, the scene's own (design.model: scene or lumped)")
    enabled = load_scene_like(scene, ["adaptation.enabled=true"])
    check_adaptation(enabled)
    change = scene.events[0].time
    if change < scene.controller.start:
        raise InputError(f"events[0].time: {change:g} s is before controller.start "
                         f"({scene.controller.start:g} s); the adaptation watches from there")


def load_scene_like(scene: Scene, overrides: list[str]) -> Scene:
    """``scene`` with more overrides (through its dict, checked as a file would be)."""
    return scene_from_dict(scene.to_dict(), overrides)


def true_frequencies(scene: Scene, count: int) -> list[float]:
    """The lowest ``count`` natural frequencies [Hz] of the plant's model after all of the
    scene's events, linearised (|λ| / 2π, as the identification reports them)."""
    return design_frequencies(build_model(changed_scene(scene, len(scene.events))))[
        :count].tolist()


def summarize(scene: Scene, results: dict[str, LaunchResult]) -> dict[str, Any]:
    """The result document (module docstring)."""
    adaptive = results["adaptive"].evaluation
    change = adaptive["structure_events"][0]["applied_s"]
    events = adaptive.get("adaptation", {}).get("events", [])
    detection = next((e for e in events if e["kind"] == "detection" and e["t"] > change), None)
    design = next((e for e in events if e["kind"] == "design" and e["t"] > change), None)
    identified = design["identified_hz"] if design else None
    truth = true_frequencies(scene, len(identified) if identified else 4)
    reductions = {name: results[name].evaluation["reduction_pct"] for name in RUNS}
    share = [a / o if o > 0 else float("nan") for a, o in zip(
        reductions["adaptive"]["displacement"], reductions["oracle"]["displacement"],
        strict=True)]
    errors = (np.abs(np.array(identified) / truth - 1.0).tolist()
              if identified and len(identified) == len(truth) else None)
    delay = None if detection is None else detection["t"] - change
    targets = {
        "detection_within_s": DETECTION_S,
        "detection_met": delay is not None and delay <= DETECTION_S,
        "frequency_error_within": FREQUENCY_ERROR,
        "frequency_met": errors is not None and max(errors) <= FREQUENCY_ERROR,
        "oracle_share_at_least": ORACLE_SHARE,
        "oracle_share_met": all(s >= ORACLE_SHARE for s in share),
    }
    return {
        "scene": scene.name,
        "adaptation": {"change_at_s": change,
                       "detected_at_s": None if detection is None else detection["t"],
                       "identified_hz": identified, "true_hz": truth,
                       "reduction_pct": reductions},
        "details": {
            "detection_delay_s": delay,
            "onset_estimate_s": None if detection is None else detection["onset_s"],
            "handover_s": design["handover_s"] if design else None,
            "identification_window_s": design["window_s"] if design else None,
            "design_hz": design["design_hz"] if design else None,
            "frequency_error": errors,
            "adaptive_over_oracle_displacement": share,
            "refusals": [e for e in events if e["kind"] == "refusal"],
            "threshold": scene.adaptation.threshold,
            "targets": targets,
            "runs": {name: str(results[name].result_file.parent) for name in RUNS},
        },
    }


def run_adaptation_experiment(scene_path: Path, overrides: Sequence[str], *, out: Path,
                              progress: Callable[[str], None] | None = None,
                              ) -> tuple[dict[str, Any], dict[str, LaunchResult]]:
    """The three launches (module docstring) into ``out/<run>``; the document and the runs."""
    scene = load_scene(scene_path, list(overrides))
    check_experiment(scene)
    results = {}
    for name, sets in run_overrides(scene, overrides).items():
        if progress:
            progress(f"{name} run through the nodes (lock-step)")
        results[name] = run_scene(scene_path, sets, out=out / name)
    return summarize(scene, results), results
