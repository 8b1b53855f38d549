"""Work-precision measurements: every model × integrator × step against a converged reference.

The reference is the FE model with 40 elements per column integrated by the compiled implicit
midpoint rule at ``REFERENCE_DT`` and checked by Richardson's estimate against a run at twice
the step (order 2: error(h) ≈ |x_h − x_2h| / 3). Errors are measured on the outputs the rig
measures — floor displacements x1..x3 and the pendulum angle φ — on a common 10 ms grid, as
max_t |y − y_ref| / max_t |y_ref| per channel, the worst channel counting. Cost is CPU time
(``time.process_time``) of the compiled kernels per simulated second.

The port-Hamiltonian rows (``ph1``, ``ph3``: the frame pHDAE by its compiled AVF midpoint step,
:mod:`stillframe.dynamics.ph.frame_step`) are measured alike, against the same reference, and
also report their discrete energy-balance error: the largest |ΔH − h(ȳᵀū − ν̄ᵀRν̄)| of a step over
the largest H of the run (or :data:`ENERGY_FLOOR_J`). The FrameModel kernels (RK4, implicit
midpoint on M(q)q̈ = Q) keep no discrete power balance; their ``energy_error`` is None.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from stillframe.config.scene import Scene, scene_from_dict
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.integrators import NO_SUBDIVISION
from stillframe.dynamics.kernels import CompiledFrame
from stillframe.dynamics.models import FrameModel, build_model
from stillframe.dynamics.ph import scene_model as ph_scene
from stillframe.dynamics.simulation import initial_state
from stillframe.dynamics.stability import rk4_stable_step

REFERENCE_MODEL = ("fe", 40)
REFERENCE_DT = 1e-5
GRID_DT = 1e-2
STEPS = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4)
QUICK_STEPS = (5e-3, 1e-3, 2e-4)

# name: scene overrides; all use modal damping, the one damping valid for every model
SCENES: dict[str, list[str]] = {
    "hammer": ["excitation.type=hammer", "excitation.impulse=0.05", "excitation.time=0.01",
               "excitation.width=0.005"],
    "worst_case": ["excitation.type=harmonics", "excitation.amplitudes=[0.1, 0.1, 0.1]",
                   "excitation.frequencies_hz=[1.9, 5.7, 8.8]"],
    "swing": ["initial.phi=2.5"],
}
# frequency content of each scene [Hz]: harmonics up to 8.8 Hz and the free swing (modes up to
# 8.5 Hz) lie below 10 Hz; a half-sine blow of width T has |F(f)/F(0)| = |cos πfT / (1 − 4f²T²)|,
# 0.33 (−10 dB) at f = 1/T = 200 Hz for T = 5 ms, and its first zero at 1.5/T.
SCENE_BANDS_HZ: dict[str, tuple[float, float]] = {
    "hammer": (0.0, 200.0), "worst_case": (0.0, 10.0), "swing": (0.0, 10.0)}
MODELS: dict[str, list[str]] = {
    "lumped": ["model.type=lumped"],
    **{f"fe{n}": ["model.type=fe", f"model.elements_per_column={n}"] for n in (1, 3, 10, 40)},
    **{f"modal{r}": ["model.type=modal", "model.elements_per_column=40", f"model.modes={r}"]
       for r in (3, 6, 12)},
    **{f"ph{n}": ["model.type=ph", f"model.elements_per_column={n}"] for n in (1, 3)},
}
QUICK_MODELS = ("lumped", "fe1", "fe3", "modal3", "ph3")
METHODS = ("rk4", "midpoint")
#: the energy below which a run counts as at rest for its balance error (the hammer at a 10 ms
#: step samples the 5 ms blow at its zero: H stays ~1e-35 J, and round-off of that is no measure)
ENERGY_FLOOR_J = 1e-20
#: the pH rows' one integrator: the AVF implicit midpoint rule of the pHDAE
PH_METHODS = ("midpoint",)

Progress = Callable[[str], None]


@dataclass
class Point:
    """One run of the work-precision sweep."""

    scene: str
    model: str
    dofs: int
    method: str
    dt: float
    error: float | None  # None: not run (beyond the stability limit)
    cpu_per_s: float | None  # CPU seconds per simulated second
    note: str = ""
    energy_error: float | None = None  # discrete energy-balance error (pH rows), else None


def scene_for(scene: str, model: str, duration: float) -> Scene:
    return scene_from_dict({"name": f"{scene}-{model}"}, [
        "damping.model=modal", *SCENES[scene], *MODELS[model], f"duration={duration}"])


def outputs(model: FrameModel, states: np.ndarray) -> np.ndarray:
    """Floor displacements and φ (columns) of a run's states."""
    return states[:, [*model.floor_index, model.phi_index]]


def run_outputs(frame: CompiledFrame, scene: Scene, method: str, dt: float,
                repeat_until: float = 0.0) -> tuple[np.ndarray, float]:
    """Outputs on the 10 ms grid and the CPU time per run (repeated to ``repeat_until`` s) of
    ``frame`` (built from ``scene``'s model)."""
    model = frame.model
    load = floor_load(scene.excitation, scene.duration)
    x0 = initial_state(model, scene.initial)
    stride = round(GRID_DT / dt)
    n = round(scene.duration / dt)
    frame.run(method, x0, dt, 1, load=load)  # compile and factor outside the clock
    runs, start = 0, time.process_time()
    while True:
        states = frame.run(method, x0, dt, n, load=load, stride=stride)
        runs += 1
        spent = time.process_time() - start
        if spent >= repeat_until:
            break
    return outputs(model, states), spent / runs


def relative_error(y: np.ndarray, reference: np.ndarray) -> float:
    scale = np.max(np.abs(reference), axis=0)
    return float(np.max(np.max(np.abs(y - reference), axis=0) / scale))


@dataclass
class Reference:
    scene: str
    outputs: np.ndarray
    richardson_error: float
    cpu_s: float


def _reference_job(job: tuple[str, float]) -> Reference:
    return reference(*job)


def reference(scene: str, duration: float) -> Reference:
    """FE 40 by the implicit midpoint at REFERENCE_DT, Richardson-checked against 2·REFERENCE_DT."""
    s = scene_for(scene, f"fe{REFERENCE_MODEL[1]}", duration)
    frame = CompiledFrame(build_model(s))
    fine, cpu = run_outputs(frame, s, "midpoint", REFERENCE_DT)
    coarse, _ = run_outputs(frame, s, "midpoint", 2 * REFERENCE_DT)
    return Reference(scene, fine, relative_error(coarse, fine) / 3.0, cpu)


def ph_outputs(scene: Scene, dt: float, repeat_until: float = 0.0,
               ) -> tuple[np.ndarray, float, float]:
    """A pH run: outputs on the 10 ms grid, CPU time per run (repeated to ``repeat_until`` s)
    and the largest per-step energy-balance residual over the largest H (a run kept per step,
    not timed)."""
    fs = ph_scene.scene_frame(scene)
    stepper = fs.stepper(dt)
    z0 = stepper.reduce(ph_scene.initial_state(fs.system, scene))
    load = floor_load(scene.excitation, scene.duration)
    n, stride = round(scene.duration / dt), round(GRID_DT / dt)
    loads = np.zeros((n, 3))
    if load is not None:
        loads[:, load.excitation.floor - 1] = load.force_at((np.arange(n) + 0.5) * dt)
    zero = np.zeros(4)
    stepper.run(z0.copy(), loads[:1], zero, zero)   # compile outside the clock
    runs, start = 0, time.process_time()
    while True:
        z = z0.copy()
        record, _ = stepper.run(z, loads, zero, zero)
        runs += 1
        spent = time.process_time() - start
        if spent >= repeat_until:
            break
    states = np.empty((n + 1, z0.size))
    states[0] = z = z0.copy()
    _, energy = stepper.run(z, loads, zero, zero, states=states[1:])
    residual = stepper.energy_changes(states) - energy[:, :3].sum(axis=1) + energy[:, 3]
    scale = max(float(np.max(stepper.energies(states))), ENERGY_FLOOR_J)
    balance = float(np.max(np.abs(residual)) / scale)
    first = stepper.readings(z0)
    y = np.vstack([np.r_[first["floors"][0], first["phi"][0]],
                   np.column_stack([record[:, :3], stepper.readings(states[1:])["phi"]])])
    return y[::stride], spent / runs, balance


def model_points(job: tuple[str, str, float, tuple[float, ...], np.ndarray]) -> list[Point]:
    """One scene × model of the sweep: every method and step against the reference outputs."""
    scene, name, duration, steps, ref_outputs = job
    s = scene_for(scene, name, duration)
    if s.model.type == "ph":
        points = []
        for dt in steps:
            y, cpu, balance = ph_outputs(s, dt, repeat_until=0.02)
            dofs = ph_scene.scene_frame(s).system.n
            points.append(Point(scene, name, dofs, PH_METHODS[0], dt,
                                relative_error(y, ref_outputs), cpu / duration,
                                "pHDAE, AVF midpoint", balance))
        return points
    model = build_model(s)
    frame = CompiledFrame(model, NO_SUBDIVISION)  # each method at its own step, never halved
    limit = rk4_stable_step(model)
    points = []
    for method in METHODS:
        for dt in steps:
            if method == "rk4" and dt > limit:
                points.append(Point(scene, name, model.n_dof, method, dt, None, None,
                                    f"beyond RK4 stability limit {limit:.3g} s"))
                continue
            y, cpu = run_outputs(frame, s, method, dt, repeat_until=0.02)
            points.append(Point(scene, name, model.n_dof, method, dt,
                                relative_error(y, ref_outputs), cpu / duration))
    return points


Mapper = Callable[[Callable, list], list]


def sweep(*, quick: bool = False, duration: float | None = None,
          progress: Progress | None = None, mapper: Mapper | None = None) -> dict:
    """The whole work-precision sweep: references, points, Pareto fronts, model frequencies.

    ``mapper(fn, items)`` runs the per-scene references and then the per-model jobs (default:
    one after the other here; :func:`stillframe.studies.executor.run_tasks` spreads them)."""
    duration = duration or (1.0 if quick else 4.0)
    steps = QUICK_STEPS if quick else STEPS
    models = QUICK_MODELS if quick else tuple(MODELS)
    say = progress or (lambda _text: None)

    def serial(fn: Callable, items: list) -> list:
        out = []
        for item in items:
            say(f"{item[0]}: {item[1] if isinstance(item[1], str) else 'reference'}")
            out.append(fn(item))
        return out

    run = mapper or serial
    refs = run(_reference_job, [(scene, duration) for scene in SCENES])
    references = {r.scene: {"richardson_error": r.richardson_error, "cpu_s": r.cpu_s}
                  for r in refs}
    jobs = [(r.scene, name, duration, steps, r.outputs) for r in refs for name in models]
    points: list[Point] = [p for group in run(model_points, jobs) for p in group]
    return {
        "reference": {
            "model": f"fe{REFERENCE_MODEL[1]}", "method": "midpoint (compiled)",
            "dt": REFERENCE_DT, "check": "Richardson against 2*dt, order 2",
            "per_scene": references,
        },
        "duration_s": duration,
        "grid_dt": GRID_DT,
        "scenes": dict(SCENES),
        "points": [asdict(p) for p in points],
        "pareto": {scene: [asdict(p) for p in pareto(points, scene)] for scene in SCENES},
    }


def pareto(points: list[Point], scene: str) -> list[Point]:
    """Runs of ``scene`` that no other run beats on both cost and error, cheapest first."""
    ran = sorted((p for p in points if p.scene == scene and p.error is not None),
                 key=lambda p: (p.cpu_per_s, p.error))
    front: list[Point] = []
    for p in ran:
        if not front or p.error < front[-1].error:
            front.append(p)
    return front
