"""Scene files: what to simulate and with what fidelity (README, "Scenes").

A scene is YAML validated against :data:`SCENE_SCHEMA`; every value can be overridden with
``--set dotted.key=value``. Rig defaults are the thesis's test rig (§5.2).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

from stillframe.config.loop_sections import LOOP_SCHEMA, check_loop
from stillframe.config.schema import (
    Field,
    Section,
    in_range,
    non_negative,
    positive,
    set_dotted,
    validate,
)
from stillframe.config.yamlio import load_yaml
from stillframe.errors import InputError

RIG_SCHEMA: dict[str, Any] = {
    "floor_masses": Field("floats", [1.281, 0.814, 1.380], positive, length=3, doc="m1..m3 [kg]"),
    "columns": {
        "lengths": Field("floats", [0.23, 0.28, 0.23], positive, length=3, doc="L1..L3 [m]"),
        "width": Field(float, 0.035, positive, doc="b [m]"),
        "thickness": Field(float, 0.001, positive, doc="h [m]"),
        "density": Field(float, 7860.0, non_negative, doc="rho [kg/m^3]"),
        "youngs_modulus": Field(float, 207e9, positive, doc="E [Pa]"),
        "per_story": Field(int, 2, positive, doc="blades per story"),
    },
    "pendulum": {
        "half_length": Field(float, 0.0825, positive, doc="L4 [m]"),
        "mass": Field(float, 0.083, positive, doc="m4 [kg]"),
        "inertia": Field(float, 8.32e-4, positive, doc="Izz,4 about the centre of mass [kg m^2]"),
        "hinge_damping": Field(float, 2.432e-3, non_negative, doc="r4 [N m s/rad]"),
    },
    "gravity": Field(float, 9.81, non_negative, doc="g [m/s^2]"),
}

DAMPING_SCHEMA: dict[str, Any] = {
    "model": Field(str, "rayleigh", choices=("rayleigh", "modal", "none")),
    "alpha": Field(float, 0.9751, doc="mass-proportional coefficient [1/s]"),
    "beta": Field(float, -2.8815e-4, doc="stiffness-proportional coefficient [s]"),
    "modal_ratios": Field(
        "floats", [0.0395, 0.0030, 0.0042], in_range(0.0, 1.0),
        doc="zeta of the first structural modes (thesis ERA/DC identification, §5.5)",
    ),
    "high_mode_ratio": Field(float, 0.005, in_range(0.0, 1.0), doc="zeta of the modes above"),
}

EXCITATION_SCHEMA: dict[str, Any] = {
    "type": Field(str, "none", choices=("none", "harmonics", "hammer", "white_noise", "chirp")),
    "floor": Field(int, 1, in_range(1, 3), doc="floor the force acts on"),
    "amplitudes": Field("floats", [0.1, 0.1, 0.1], doc="harmonics: force amplitudes [N]"),
    "frequencies_hz": Field("floats", [1.9, 5.7, 8.8], non_negative, doc="harmonics [Hz]"),
    "phases": Field("floats", [], doc="harmonics: phases [rad], zeros when empty"),
    "impulse": Field(float, 0.05, doc="hammer: impulse [N s]"),
    "time": Field(float, 0.0, non_negative, doc="hammer: time of the blow [s]"),
    "width": Field(float, 5e-3, positive, doc="hammer: duration of the half-sine pulse [s]"),
    "std": Field(float, 0.1, non_negative, doc="white noise: force std [N]"),
    "rate_hz": Field(float, 1000.0, positive, doc="white noise: sample-and-hold rate [Hz]"),
    "seed": Field(int, 0, doc="white noise: random seed"),
    "amplitude": Field(float, 0.1, doc="chirp: amplitude [N]"),
    "f0_hz": Field(float, 0.5, positive, doc="chirp: start frequency [Hz]"),
    "f1_hz": Field(float, 12.0, positive, doc="chirp: end frequency [Hz]"),
    "sweep_s": Field(float, 20.0, positive, doc="chirp: sweep duration [s]"),
}

SCENE_SCHEMA: dict[str, Any] = {
    "name": Field(str, doc="scene name"),
    "description": Field(str, ""),
    "rig": RIG_SCHEMA,
    "damping": DAMPING_SCHEMA,
    "model": {
        "type": Field(str, "lumped", choices=("lumped", "fe", "modal", "ph", "auto")),
        "elements_per_column": Field(int, 3, positive),
        "modes": Field(int, 3, positive, doc="modal: retained fixed-interface column modes"),
        "band_hz": Field("floats", [0.0, 15.0], non_negative, length=2,
                         doc="auto: frequency band the scene must reproduce [Hz]"),
        "tolerance": Field(float, 0.01, in_range(1e-12, 1.0),
                           doc="auto: relative error allowed in the band"),
    },
    "integrator": {
        "method": Field(str, "rk4", choices=("rk4", "midpoint", "dop853", "radau")),
        "dt": Field(float, 1e-3, positive, doc="fixed step, or output step of adaptive methods"),
        "rtol": Field(float, 1e-10, positive),
        "atol": Field(float, 1e-12, positive),
    },
    "excitation": EXCITATION_SCHEMA,
    "initial": {
        "floors": Field("floats", [0.0, 0.0, 0.0], length=3, doc="x1..x3 [m]"),
        "phi": Field(float, 0.0, doc="pendulum angle from hanging [rad]"),
        "floor_velocities": Field("floats", [0.0, 0.0, 0.0], length=3, doc="[m/s]"),
        "phi_rate": Field(float, 0.0, doc="[rad/s]"),
    },
    "duration": Field(float, 10.0, positive, doc="[s]"),
    **LOOP_SCHEMA,
}


def _read(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(f"{path}: cannot read scene ({exc.strerror})") from None
    try:
        data = load_yaml(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise InputError(f"{path}: not valid YAML{where}") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: a scene is a mapping of keys, got {type(data).__name__}")
    return data


def apply_overrides(data: dict[str, Any], overrides: list[str]) -> None:
    """Apply ``dotted.key=value`` overrides; values are parsed as YAML (numbers, lists)."""
    for item in overrides:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise InputError(f"--set {item}: expected dotted.key=value")
        try:
            value = load_yaml(text) if text else ""
        except yaml.YAMLError:
            raise InputError(f"--set {item}: value is not valid YAML") from None
        set_dotted(data, key.strip(), value)


def _check_consistency(scene: Section) -> None:
    exc = scene.excitation
    if exc.type == "harmonics":
        n = len(exc.amplitudes)
        if len(exc.frequencies_hz) != n or (exc.phases and len(exc.phases) != n):
            raise InputError(
                "excitation: amplitudes, frequencies_hz and phases need the same length "
                f"(got {n}, {len(exc.frequencies_hz)}, {len(exc.phases)})"
            )
    if scene.integrator.dt > scene.duration:
        raise InputError(
            f"integrator.dt: {scene.integrator.dt:g} s is longer than duration {scene.duration:g} s"
        )
    if abs(scene.initial.phi) > 100 * math.pi:
        raise InputError("initial.phi: more than 50 turns; give the angle in rad")
    check_loop(scene)


def scene_from_dict(data: dict[str, Any], overrides: list[str] | None = None) -> Section:
    """Validate a scene given as a dict (after applying ``--set`` overrides).

    ``model.type: auto`` stays as given: :func:`stillframe.fidelity.auto_model.resolve_model` is
    the step that replaces it with a measured choice."""
    apply_overrides(data, overrides or [])
    scene = validate(SCENE_SCHEMA, data)
    _check_consistency(scene)
    return scene


def load_scene(path: str | Path, overrides: list[str] | None = None) -> Section:
    """Load, override and validate a scene file; raise InputError naming the key on any problem."""
    return scene_from_dict(_read(Path(path)), overrides)
