"""The thesis's chapter end to end through the nodes: identify, then control (thesis §5.5–5.6).

For a scene (its plant: the nonlinear lumped or FE model, or an identified linear one):

1. **Identification test** through sim_node (lock-step by default), recorded by
   ``stillframe record``: the plant open loop under a white-noise force on floor 1 held over each
   sample period (a shaker driven at the sampling rate). A force held over the period is what the
   discrete model and MKR assume (zero-order hold, eq. 3.43), so the load cell's samples measure
   the input exactly; the excitation is flat up to the Nyquist frequency (16 Hz at 32 Hz),
   above the three structural modes.
2. **OKID + ERA/DC + MKR** on the bag: :mod:`stillframe.identification.structure_model`,
   written as an identified-model file.
3. **LQG design** on it (``design.model: file``) in estimator_node and controller_node.
4. **Closed loop** on the plant through the three nodes.
5. The same loop **designed on the true model** (``design.model: scene``, or the plant's file).

The loop is the scene's own when it has an LQG controller, else (no controller, or another kind:
the experiment compares LQG designs) the thesis's LQG set-up (§5.6:
Kalman filter, eq. 5.229–5.230 weights, control from 25 s of 50 s, 10 s windows) with the torque
limited to 0.05 N m in controller and actuator (:data:`LQG_LOOP`). ``--set`` overrides apply to
both runs and to the test, except what the test must be (excitation, no controller, duration).
"""

from __future__ import annotations

import json
import math
import shutil
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.experiment_test_force import test_force
from stillframe.app.launcher import run_scene
from stillframe.bags.channels import Channel, read_record
from stillframe.config.scene import load_scene, steps_in
from stillframe.config.schema import Section
from stillframe.contract import topics
from stillframe.design.identified import load_identified_structure, resolve_model_file
from stillframe.dynamics.models import build_model
from stillframe.errors import IdentificationError, InputError
from stillframe.files import write_text
from stillframe.identification.structure_model import (
    IdentifiedStructure,
    identify_structure,
    save_structure,
)

#: the thesis's LQG loop (scenes/thesis_lqg.yaml) on the scene's plant, torque limited
LQG_LOOP: tuple[str, ...] = (
    "estimator.type=kf", "controller.type=lqg", "controller.start=25", "duration=50",
    "evaluation.window=10", "sensors.accelerometer_noise_std=1e-3",
    "sensors.encoder_noise_std=1e-3", "actuators.torque_limit=0.05", "controller.limit=0.05",
)
#: sensor noise of the identification test unless ``--set`` says otherwise (bags/hammer's)
TEST_SENSORS: tuple[str, ...] = ("sensors.accelerometer_noise_std=1e-3",
                                 "sensors.load_cell_noise_std=1e-3")
INPUT_TOPIC = "/frame/" + topics.EXCITATION_WRENCH.name
OUTPUT_TOPICS = tuple("/frame/" + t.name for t in topics.FLOOR_IMU)
#: the rate the identification runs at (the rig's; Nyquist 16 Hz above the 8.8 Hz top mode)
IDENTIFICATION_RATE_HZ = 32.0
#: what a run writes into its output directory (cleared on the next run)
OUTPUTS = ("test", "bag", "model.npz", "true_design", "identified_design", "comparison.png",
           "experiment.json")
MARKER = "experiment.json"
Progress = Callable[[str], None]


@dataclass(frozen=True)
class IdentificationTest:
    """The identification test: force std [N], duration [s], noise seed."""

    force_std: float | None = None
    """None: :func:`stillframe.app.experiment_test_force.test_force` chooses it."""
    duration: float = 64.0
    seed: int = 0

    def check(self) -> None:
        if self.force_std is not None and not (self.force_std > 0
                                               and math.isfinite(self.force_std)):
            raise InputError(f"--test-force {self.force_std:g}: must be a positive force [N]")
        if not (self.duration > 0 and math.isfinite(self.duration)):
            raise InputError(f"--test-duration {self.duration:g}: must be positive [s]")


@dataclass
class ExperimentResult:
    """What the five steps produced."""

    scene: Section
    loop: Section
    identified: IdentifiedStructure
    samples: int
    dt: float
    true_structure: dict[str, np.ndarray] | None
    evaluation: dict[str, dict[str, Any]]
    histories: dict[str, Path]
    files: dict[str, str] = field(default_factory=dict)


def integrator_override(scene: Section) -> list[str]:
    """``integrator.dt`` lowered to divide the sample period, when it does not already."""
    period = 1.0 / scene.sensors.rate_hz
    if steps_in(period, scene.integrator.dt) is not None:
        return []
    return [f"integrator.dt={period / math.ceil(period / scene.integrator.dt):.17g}"]


def identification_test_overrides(scene: Section, user: Sequence[str],
                                  test: IdentificationTest) -> list[str]:
    """The identification test's overrides after ``user`` (the scene's own, with an integrator
    step that divides the period): white noise on floor 1 held over a sample period."""
    return [*TEST_SENSORS, *user,
            "excitation.type=white_noise", "excitation.floor=1",
            f"excitation.std={test_force(scene, test.force_std):.17g}",
            f"excitation.rate_hz={scene.sensors.rate_hz:.17g}", f"excitation.seed={test.seed}",
            "estimator.type=none", "controller.type=none", f"duration={test.duration:.17g}"]


def loop_overrides(scene: Section, user: Sequence[str]) -> list[str]:
    """The closed loop's overrides (before the design): the scene's LQG loop or :data:`LQG_LOOP`."""
    if scene.excitation.type == "none":
        raise InputError("excitation.type: none; the closed loop needs a disturbance to reduce "
                         "(e.g. the thesis's harmonics of scenes/thesis_lumped.yaml)")
    loop = [] if scene.controller.type == "lqg" else list(LQG_LOOP)
    return [*loop, *user]


def true_design(scene: Section) -> list[str]:
    """Design on the plant's own model: its file, or the scene's model."""
    if scene.plant.model == "file":
        return ["design.model=file", f"design.file={scene.plant.file}"]
    return ["design.model=scene"]


def true_structure(scene: Section) -> dict[str, np.ndarray] | None:
    """The plant's floors-only M, K, R where they exist (lumped or an identified plant file)."""

    if scene.plant.model == "file":
        s = load_identified_structure(resolve_model_file(scene.plant.file, "plant.file"))
    elif scene.model.type == "lumped":
        s = build_model(scene).structure
    else:
        return None
    return {"M": s.mass, "K": s.stiffness, "R": s.damping}


def identification_decimation(scene: Section) -> int:
    """The decimation that brings the sensors' rate down to about :data:`IDENTIFICATION_RATE_HZ`
    (1 at the rig's 32 Hz). At 1 kHz the three modes (2–9 Hz) sit within 0.06 rad of z = 1 and an
    order-6 realization is ill-conditioned: thesis_euk_pendulum's 64000 samples gave a real
    eigenvalue and no MKR."""
    return max(1, int(scene.sensors.rate_hz // IDENTIFICATION_RATE_HZ))


def clear_previous(out: Path) -> None:
    """Remove what an earlier experiment wrote into ``out``; refuse any other non-empty DIR."""
    if not out.exists():
        return
    if not out.is_dir():
        raise InputError(f"--out {out}: not a directory")
    if any(out.iterdir()) and not (out / MARKER).is_file():
        raise InputError(f"--out {out}: not empty and not an earlier experiment; choose another")
    for name in OUTPUTS:
        path = out / name
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)


def _stderr(message: str) -> None:
    print(f"experiment: {message}", file=sys.stderr, flush=True)


def run_experiment(scene_path: Path, user: Sequence[str], out: Path, test: IdentificationTest, *,
                   mode: str = "lockstep", lockstep_timeout_s: float | None = None,
                   backends: Sequence[str] = (), progress: Progress = _stderr
                   ) -> ExperimentResult:
    """Steps 1–5 of the module docstring; files go to ``out``."""

    test.check()
    probe = load_scene(scene_path, [*user, "controller.type=none"])  # rate and step only
    user = [*integrator_override(probe), *user]
    scene = load_scene(scene_path, user)
    test = replace(test, force_std=test_force(scene, test.force_std))
    ident_set = identification_test_overrides(scene, user, test)
    loop_base = loop_overrides(scene, user)
    model_file = (out / "model.npz").resolve()
    designs = {"true_design": [*loop_base, *true_design(scene)],
               "identified_design": [*loop_base, "design.model=file", f"design.file={model_file}"]}
    load_scene(scene_path, ident_set)
    loop = load_scene(scene_path, designs["true_design"])  # both checked before anything runs
    clear_previous(out)
    out.mkdir(parents=True, exist_ok=True)
    write_summary(out, {"status": "running", "scene": str(scene_path)})

    progress(f"[1/5] identification test: white noise {test.force_std:g} N on floor 1 held at "
             f"{scene.sensors.rate_hz:g} Hz, {test.duration:g} s, through sim_node ({mode}), "
             f"recorded to {out / 'bag'}")
    run_scene(scene_path, ident_set, out=out / "test", mode=mode, record_dir=out / "bag",
              lockstep_timeout_s=lockstep_timeout_s, record_topics=[INPUT_TOPIC, *OUTPUT_TOPICS],
              backends=backends)
    progress("[2/5] OKID + ERA/DC (order 6) + MKR on the bag")
    record = read_record(out / "bag", [Channel(INPUT_TOPIC)], [Channel(t) for t in OUTPUT_TOPICS],
                         decimate=identification_decimation(scene))
    try:
        identified = identify_structure(record.u, record.y, record.dt, scene.rig)
    except (InputError, IdentificationError) as exc:
        raise type(exc)(f"the test in {out / 'bag'} ({test.force_std:g} N, {record.samples} "
                        f"samples) did not identify the structure: {exc}") from None
    save_structure(model_file, identified, [str(c) for c in record.inputs],
                   [str(c) for c in record.outputs], {"bag": str(out / "bag")})
    evaluation, histories = {}, {}
    for step, (name, overrides) in enumerate(
            (("identified_design", designs["identified_design"]),
             ("true_design", designs["true_design"])), start=3):
        what = "the identified model" if name == "identified_design" else "the true model"
        progress(f"[{step}/5] LQG designed on {what}: closed loop through the three nodes")
        result = run_scene(scene_path, overrides, out=out / name, mode=mode,
                           lockstep_timeout_s=lockstep_timeout_s, backends=backends)
        evaluation[name], histories[name] = result.evaluation, result.history_file
    return ExperimentResult(scene, loop, identified, record.samples, record.dt,
                            true_structure(loop), evaluation, histories,
                            {"bag": str(out / "bag"), "model": str(model_file)})


def write_summary(out: Path, document: dict[str, Any]) -> None:
    """``experiment.json`` in ``out`` (also the marker that lets the next run clear ``out``)."""
    write_text(out / MARKER, json.dumps(document, indent=2) + "\n", what="experiment summary")
