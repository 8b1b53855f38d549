"""Scene files: what to simulate and with what fidelity (README, "Scenes").

A scene is YAML validated into a :class:`Scene`, frozen dataclasses whose fields declare every key
with its type, default, check and doc; every value can be overridden with
``--set dotted.key=value``. Rig defaults are the thesis's test rig (§5.2).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import yaml

from stillframe.config.events import (
    FACTOR_RANGE,
    MAX_EVENTS,
    Event,
    changed_keys,
    check_event,
    damping_changes,
    first_sample_at,
)
from stillframe.config.loop_sections import (
    Actuators,
    Adaptation,
    Controller,
    Design,
    Estimator,
    Evaluation,
    Plant,
    Sensors,
)
from stillframe.config.schema import (
    SEED_RANGE,
    Floats,
    Floats2,
    Floats3,
    Section,
    in_range,
    key,
    magnitude,
    section,
    set_dotted,
    show,
    up_to,
    validate,
)
from stillframe.config.yamlio import MAX_YAML_BYTES, load_yaml, problem
from stillframe.errors import InputError
from stillframe.files import read_bytes

__all__ = ["DAMPING_COEFFICIENT", "FLOOR_MASS", "FREQUENCY_HZ", "Columns", "Damping", "Excitation",
           "Initial", "Integrator", "Model", "Pendulum", "Rig", "Scene", "apply_overrides",
           "changed_scene", "event_changes", "load_scene", "sample_grid", "scene_from_dict",
           "steps_in"]

#: the finite-element mesh and the modal model's modes at most (matrices of 3 * 2 * n + 1)
MAX_ELEMENTS = 200
#: integrator steps of one run at most (duration / integrator.dt): the simulator keeps a row
#: of 7 values per step (1e7 steps: 560 MB)
MAX_STEPS = 10_000_000
#: a floor's mass [kg]: rig.floor_masses, and an identified model's masses (its mass matrix's
#: diagonal, contract/model_file.py)
FLOOR_MASS = in_range(1e-6, 1e7)
#: a frequency of the rig [Hz]: excitation.frequencies_hz, and an identified model's natural
#: frequencies
FREQUENCY_HZ = in_range(0.0, 1e5)
#: a damping coefficient [N m s/rad, N s/m]: rig.pendulum.hinge_damping, and an identified
#: model's damping matrix's diagonal
DAMPING_COEFFICIENT = in_range(0.0, 1e9)


@dataclass(frozen=True, kw_only=True)
class Columns(Section):
    """rig.columns: the steel blades of each story (§5.2)."""

    lengths: Floats3 = key((0.23, 0.28, 0.23), in_range(1e-4, 100.0), doc="L1..L3 [m]")
    width: float = key(0.035, in_range(1e-6, 10.0), doc="b [m]")
    thickness: float = key(0.001, in_range(1e-6, 1.0), doc="h [m]")
    density: float = key(7860.0, in_range(0.0, 1e5), doc="rho [kg/m^3]")
    youngs_modulus: float = key(207e9, in_range(1e3, 1e13), doc="E [Pa]")
    per_story: int = key(2, up_to(100), doc="blades per story")
    stiffness_factors: Floats3 = key((1.0, 1.0, 1.0), in_range(*FACTOR_RANGE), doc=(
        "stories 1..3: the blades' bending stiffness EJ times this (a loosened clamp or a "
        "cracked blade: < 1), their mass unchanged [-]"))


@dataclass(frozen=True, kw_only=True)
class Pendulum(Section):
    """rig.pendulum: the pendulum of the damper, hinged on floor 3."""

    half_length: float = key(0.0825, in_range(1e-4, 100.0), doc="L4 [m]")
    mass: float = key(0.083, in_range(1e-6, 1e6), doc="m4 [kg]")
    inertia: float = key(8.32e-4, in_range(1e-12, 1e9),
                         doc="Izz,4 about the centre of mass [kg m^2]")
    hinge_damping: float = key(2.432e-3, DAMPING_COEFFICIENT, doc="r4 [N m s/rad]")


@dataclass(frozen=True, kw_only=True)
class Rig(Section):
    """rig: the test rig; defaults are the thesis's (§5.2)."""

    floor_masses: Floats3 = key((1.281, 0.814, 1.380), FLOOR_MASS, doc="m1..m3 [kg]")
    columns: Columns = section(Columns)
    pendulum: Pendulum = section(Pendulum)
    gravity: float = key(9.81, in_range(0.0, 100.0), doc="g [m/s^2]")


@dataclass(frozen=True, kw_only=True)
class Damping(Section):
    """damping: structural damping of the frame."""

    model: Literal["rayleigh", "modal", "none"] = key("rayleigh")
    alpha: float = key(0.9751, magnitude(1e6), doc="mass-proportional coefficient [1/s]")
    beta: float = key(-2.8815e-4, magnitude(1.0), doc="stiffness-proportional coefficient [s]")
    modal_ratios: Floats = key(
        (0.0395, 0.0030, 0.0042), in_range(0.0, 1.0),
        doc="zeta of the first structural modes (thesis ERA/DC identification, §5.5)",
    )
    high_mode_ratio: float = key(0.005, in_range(0.0, 1.0), doc="zeta of the modes above")


@dataclass(frozen=True, kw_only=True)
class Excitation(Section):
    """excitation: the force on one floor."""

    type: Literal["none", "harmonics", "hammer", "white_noise", "chirp"] = key("none")
    floor: int = key(1, in_range(1, 3), doc="floor the force acts on")
    amplitudes: Floats = key((0.1, 0.1, 0.1), magnitude(1e9), doc="harmonics: force amplitudes [N]")
    frequencies_hz: Floats = key((1.9, 5.7, 8.8), FREQUENCY_HZ, doc="harmonics [Hz]")
    phases: Floats = key((), magnitude(1e6), doc="harmonics: phases [rad], zeros when empty")
    impulse: float = key(0.05, magnitude(1e9), doc="hammer: impulse [N s]")
    time: float = key(0.0, in_range(0.0, 1e6), doc="hammer: time of the blow [s]")
    width: float = key(5e-3, up_to(1e3), doc="hammer: duration of the half-sine pulse [s]")
    std: float = key(0.1, in_range(0.0, 1e9), doc="white noise: force std [N]")
    rate_hz: float = key(1000.0, up_to(1e6), doc="white noise: sample-and-hold rate [Hz]")
    seed: int = key(0, in_range(*SEED_RANGE), doc="white noise: random seed")
    amplitude: float = key(0.1, magnitude(1e9), doc="chirp: amplitude [N]")
    f0_hz: float = key(0.5, up_to(1e5), doc="chirp: start frequency [Hz]")
    f1_hz: float = key(12.0, up_to(1e5), doc="chirp: end frequency [Hz]")
    sweep_s: float = key(20.0, up_to(1e6), doc="chirp: sweep duration [s]")


@dataclass(frozen=True, kw_only=True)
class Model(Section):
    """model: which dynamics model simulates the rig."""

    type: Literal["lumped", "fe", "modal", "ph", "auto"] = key("lumped")
    elements_per_column: int = key(3, up_to(MAX_ELEMENTS), doc="fe: mesh size")
    modes: int = key(3, up_to(MAX_ELEMENTS), doc="modal: retained fixed-interface column modes")
    band_hz: Floats2 = key((0.0, 15.0), in_range(0.0, 1e5),
                                       doc="auto: frequency band the scene must reproduce [Hz]")
    tolerance: float = key(0.01, in_range(1e-12, 1.0),
                           doc="auto: relative error allowed in the band")
    energy_tolerance: float | None = key(None, in_range(1e-16, 1.0), doc=(
        "auto: energy consistency asked for: the largest discrete energy-balance error per step "
        "allowed, relative to the stored energy (only runs that measure one qualify: ph)"))


@dataclass(frozen=True, kw_only=True)
class Integrator(Section):
    """integrator: the time integration of the model."""

    method: Literal["rk4", "midpoint", "dop853", "radau"] = key("rk4")
    dt: float = key(1e-3, in_range(1e-9, 1.0),
                    doc="fixed step, or output step of adaptive methods [s]")
    rtol: float = key(1e-10, in_range(1e-15, 1.0))
    atol: float = key(1e-12, in_range(1e-300, 1.0))
    max_halvings: int = key(12, in_range(0, 40), doc=(
        "fixed steps: a step whose Newton iteration fails, whose result is not finite or whose "
        "RK4 error estimate is too large is halved again and again down to dt / 2^max_halvings "
        "(0: such a step is an error at once)"))
    error_limit: float | None = key(1e-5, up_to(1.0), doc=(
        "RK4: largest embedded local error estimate per step, relative to 1 + |x| "
        "(null: no estimate)"))


@dataclass(frozen=True, kw_only=True)
class Initial(Section):
    """initial: the state at t = 0."""

    floors: Floats3 = key((0.0, 0.0, 0.0), magnitude(100.0), doc="x1..x3 [m]")
    phi: float = key(0.0, doc="pendulum angle from hanging [rad]")
    floor_velocities: Floats3 = key((0.0, 0.0, 0.0), magnitude(1e3), doc="[m/s]")
    phi_rate: float = key(0.0, magnitude(1e4), doc="[rad/s]")


@dataclass(frozen=True, kw_only=True)
class Scene(Section):
    """A validated scene: each section's class is its key in CamelCase."""

    name: str = key(doc="scene name")
    description: str = key("")
    rig: Rig = section(Rig)
    damping: Damping = section(Damping)
    model: Model = section(Model)
    integrator: Integrator = section(Integrator)
    excitation: Excitation = section(Excitation)
    initial: Initial = section(Initial)
    duration: float = key(10.0, up_to(1e6), doc="[s]")
    plant: Plant = section(Plant)
    sensors: Sensors = section(Sensors)
    actuators: Actuators = section(Actuators)
    design: Design = section(Design)
    estimator: Estimator = section(Estimator)
    controller: Controller = section(Controller)
    evaluation: Evaluation = section(Evaluation)
    adaptation: Adaptation = section(Adaptation)
    events: tuple[Event, ...] = key((), lambda v: None if len(v) <= MAX_EVENTS else (
        f"at most {MAX_EVENTS} events"), doc=(
            "changes of the structure while the run goes on, in time order "
            "(stillframe/config/events.py)"))


def _read(path: Path) -> dict[str, Any]:
    raw = read_bytes(path, what="scene file", max_bytes=MAX_YAML_BYTES)
    try:
        data = load_yaml(raw)
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not valid YAML: {problem(exc)}") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: a scene is a mapping of keys, got {type(data).__name__}")
    return data


def apply_overrides(data: dict[str, Any], overrides: list[str]) -> None:
    """Apply ``dotted.key=value`` overrides; values are parsed as YAML (numbers, lists)."""
    for item in overrides:
        dotted, sep, text = item.partition("=")
        if not sep or not dotted:
            raise InputError(f"--set {show(item, 80, quote=False)}: expected dotted.key=value")
        try:
            value = load_yaml(text) if text else ""
        except yaml.YAMLError as exc:
            raise InputError(f"--set {show(item, 80, quote=False)}: value is not valid YAML: "
                             f"{problem(exc)}") from None
        set_dotted(data, dotted.strip(), value)


def _check_consistency(scene: Scene) -> None:
    exc = scene.excitation
    if exc.type == "harmonics":
        n = len(exc.amplitudes)
        if len(exc.frequencies_hz) != n or (exc.phases and len(exc.phases) != n):
            raise InputError(
                "excitation: amplitudes, frequencies_hz and phases need the same length "
                f"(got {n}, {len(exc.frequencies_hz)}, {len(exc.phases)})"
            )
    if scene.duration / scene.integrator.dt > MAX_STEPS:
        raise InputError(
            f"duration: {scene.duration:g} s at integrator.dt {scene.integrator.dt:g} s is "
            f"{scene.duration / scene.integrator.dt:.3g} steps; at most {MAX_STEPS:.0e} "
            "(a shorter run or a longer step)")
    if scene.integrator.dt > scene.duration:
        raise InputError(
            f"integrator.dt: {scene.integrator.dt:g} s is longer than duration {scene.duration:g} s"
        )
    if abs(scene.initial.phi) > 100 * math.pi:
        raise InputError("initial.phi: more than 50 turns; give the angle in rad")
    _check_loop(scene)
    _check_events(scene)


#: how far ``period / integrator.dt`` may lie from a whole number, relative: the two are decimal
#: values in a scene, so a step that divides the period gives a ratio within rounding of one
DIVIDES_TOLERANCE = 1e-6


def steps_in(period: float, dt: float) -> int | None:
    """How many steps of ``dt`` make ``period``; None when ``dt`` does not divide it (within
    :data:`DIVIDES_TOLERANCE`)."""
    ratio = period / dt
    steps = round(ratio)
    return steps if steps >= 1 and abs(ratio - steps) <= DIVIDES_TOLERANCE * ratio else None


def sample_grid(scene: Scene) -> tuple[float, int]:
    """The loop's sample period 1/``sensors.rate_hz`` and the integrator steps in one period;
    InputError naming ``integrator.dt`` when it does not divide the period."""
    period = 1.0 / scene.sensors.rate_hz
    steps = steps_in(period, scene.integrator.dt)
    if steps is None:
        raise InputError(
            f"integrator.dt: {scene.integrator.dt:g} s does not divide the sample period "
            f"{period:g} s (1/sensors.rate_hz)")
    return period, steps


def _check_loop(scene: Scene) -> None:
    """Cross-field checks of the closed-loop sections (only for scenes with a controller)."""
    c, window = scene.controller, scene.evaluation.window
    if c.type == "none":
        return
    period = 1.0 / scene.sensors.rate_hz
    if period > scene.duration:
        raise InputError(f"sensors.rate_hz: one period ({period:g} s) is longer than duration")
    sample_grid(scene)
    before = scene.evaluation.baseline == "before_start"
    if (before and c.start - window < -1e-9) or c.start + window > scene.duration + 1e-9:
        where = "before controller.start ({c.start:g} s) and " if before else ""
        raise InputError(
            f"evaluation.window: {window:g} s does not fit {where.format(c=c)}after "
            f"controller.start ({c.start:g} s) within duration {scene.duration:g} s")
    if window < scene.integrator.dt * (1.0 - 1e-9):
        raise InputError(
            f"evaluation.window: {window:g} s is shorter than one integrator step "
            f"(integrator.dt {scene.integrator.dt:g} s): a peak needs at least one state in it")
    acting = c.start + scene.actuators.delay_periods * period
    if acting > scene.duration - 1e-9:
        raise InputError(
            f"actuators.delay_periods: {scene.actuators.delay_periods} periods of {period:g} s "
            f"after controller.start ({c.start:g} s) the first command acts at {acting:g} s, "
            f"when the run has ended (duration {scene.duration:g} s): no controlled state to "
            "evaluate")
    if c.type == "mpc" and c.horizon_s < period * (1.0 - 1e-9):
        raise InputError(
            f"controller.horizon_s: {c.horizon_s:g} s is shorter than one sample period "
            f"({period:g} s, 1/sensors.rate_hz)")
    if c.type == "lqg" and scene.estimator.type == "ekf":
        raise InputError("estimator.type: LQG works on a linear model; use kf, tvkf or truth")
    if scene.estimator.type == "none":
        raise InputError(f"estimator.type: {c.type} needs a state (kf, tvkf, ekf or truth)")


def _check_events(scene: Scene) -> None:
    """The events' checks that need the rest of the scene (:mod:`stillframe.config.events`)."""
    period = 1.0 / scene.sensors.rate_hz
    last = round(scene.duration / period) - 1      # the run's last sample (LoopSpec.samples)
    previous = 0.0
    for i, event in enumerate(scene.events):
        name = f"events[{i}]"
        if first_sample_at(event.time, period) > last:
            raise InputError(
                f"{name}.time: {event.time:g} s is past the run's last sample boundary "
                f"({last * period:g} s; duration {scene.duration:g} s)")
        if event.time < previous:
            raise InputError(f"{name}.time: {event.time:g} s is before events[{i - 1}] "
                             f"({previous:g} s); list the events in time order")
        previous = event.time
        check_event(name, event, scene.damping.model)
        rig = changed_scene(scene, i + 1).rig
        try:                  # the structure after it within the rig section's own bounds
            validate(Rig, rig.to_dict(), prefix="rig.")
        except InputError as exc:
            raise InputError(f"{name}: the structure after it: {exc}") from None
    after = scene.design.after_events
    if after > len(scene.events):
        raise InputError(f"design.after_events: {after}, but the scene has "
                         f"{len(scene.events)} events")
    if after and scene.design.model == "file":
        raise InputError("design.after_events: the design is the identified model of "
                         "design.file, which no event changes; use design.model: scene or lumped")
    if not scene.events:
        return
    if scene.plant.model == "file":
        raise InputError(
            "events: plant.model: file is a fixed identified linear model; events change the "
            "scene's lumped or fe plant (plant.model: scene)")
    if scene.model.type not in ("lumped", "fe"):
        raise InputError(
            f"events: model.type: {scene.model.type}: events change the lumped and fe plants "
            "(a modal plant's reduced basis and a ph plant's constraints belong to one "
            "structure, and auto may choose either)")


def changed_scene(scene: Scene, count: int) -> Scene:
    """``scene`` with the changes of its first ``count`` events made and no events: the scene a
    plant of the structure after event ``count`` − 1 is built from. Factors are of the scene's
    own values; a later event overrides the keys it names (:mod:`stillframe.config.events`)."""
    rig, damping = scene.rig, scene.damping
    masses = list(rig.floor_masses)
    factors: tuple[float, ...] = rig.columns.stiffness_factors
    pendulum_mass = rig.pendulum.mass
    damping_values: dict[str, Any] = {}
    for event in scene.events[:count]:
        if event.floor is not None:
            i, given = event.floor - 1, event.mass
            masses[i] = given if given is not None else rig.floor_masses[i] * (
                event.mass_factor or 1.0)
        if event.story_stiffness is not None:
            factors = tuple(f * g for f, g in zip(rig.columns.stiffness_factors,
                                                  event.story_stiffness, strict=True))
        if event.pendulum_mass is not None:
            pendulum_mass = event.pendulum_mass
        damping_values |= damping_changes(event)
    replace = dataclasses.replace
    rig = replace(rig, floor_masses=tuple(masses),
                  columns=replace(rig.columns, stiffness_factors=factors),
                  pendulum=replace(rig.pendulum, mass=pendulum_mass))
    return replace(scene, rig=rig, damping=replace(damping, **damping_values), events=())


def event_changes(scene: Scene, index: int) -> dict[str, Any]:
    """What event ``index`` of ``scene`` changes: each key it changes (dotted) with its value
    after the event, lists as lists (the record of the run's result and of the simulator's
    topic)."""
    after: Any = changed_scene(scene, index + 1)
    values = {}
    for dotted in changed_keys(scene.events[index]):
        value = after
        for part in dotted.split("."):
            value = getattr(value, part)
        values[dotted] = list(value) if isinstance(value, tuple) else value
    return values


def scene_from_dict(data: dict[str, Any], overrides: list[str] | None = None) -> Scene:
    """Validate a scene given as a dict (after applying ``--set`` overrides).

    ``model.type: auto`` stays as given: :func:`stillframe.fidelity.auto_model.resolve_model` is
    the step that replaces it with a measured choice."""
    apply_overrides(data, overrides or [])
    scene = validate(Scene, data)
    _check_consistency(scene)
    return scene


def load_scene(path: str | Path, overrides: list[str] | None = None) -> Scene:
    """Load, override and validate a scene file; raise InputError naming the key on any problem."""
    return scene_from_dict(_read(Path(path)), overrides)
