"""The designs a loop switches to, apart from how they were found: the scene's checks for the
adaptation (:func:`check_adaptation`), the checks every design passes before a loop takes it
(:func:`check_design`), its hand-over at a sample boundary (:class:`Handover`), and the nodes'
``design`` parameter (:class:`DesignRequest`, :class:`DesignSwitch`).

:mod:`stillframe.loop.adaptation` identifies the designs it hands over; this module imports no
identification, so a node that only switches designs (controller_node, every node's parameter
declarations) starts without it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, TypeVar

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract.signals import TORQUE, actuator_of
from stillframe.control.factory import make_controller
from stillframe.control.lqg import LQGLaw
from stillframe.control.supervisor import Controller
from stillframe.design.identified import (
    load_identified_structure,
    resolve_model_file,
    storeys_frame,
)
from stillframe.dynamics.models.frame import FrameModel
from stillframe.dynamics.models.structure import Structure
from stillframe.errors import InputError
from stillframe.estimation.base import Filter
from stillframe.estimation.factory import initial_physical, make_estimator
from stillframe.estimation.kalman import SteadyStateKalman
from stillframe.loop.wiring import design_model

__all__ = ["SCENE_DESIGN", "DesignCheck", "DesignRequest", "DesignSwitch", "Handover",
           "check_adaptation", "check_design", "design_check", "design_frequencies"]

#: the ``design`` parameter's value for the scene's own design model (``design`` section)
SCENE_DESIGN = "scene"

#: the largest pole magnitude of a design that passes (strictly inside the unit circle)
STABLE_RADIUS = 1.0 - 1e-9


def check_adaptation(scene: Scene, *, mode: str = "lockstep") -> None:
    """``adaptation``'s cross-checks with the rest of the scene and the loop's ``mode``
    (InputError naming the key): what :class:`Adaptation` needs, checked by launch before any
    process starts (:func:`stillframe.loop.parts.check_loop`)."""
    a = scene.adaptation
    if not a.enabled:
        return
    if mode != "lockstep":
        raise InputError(
            "adaptation.enabled: lock-step only; estimator_node identifies and designs inside "
            "its sample, which in real time would hold the loop for a second")
    if scene.controller.type != "lqg" or scene.estimator.type not in ("kf", "tvkf"):
        raise InputError(
            "adaptation.enabled: hands over an LQG design; needs controller.type: lqg with "
            f"estimator.type kf or tvkf (got {scene.controller.type}, {scene.estimator.type})")
    if actuator_of(scene) != TORQUE:
        raise InputError("adaptation.enabled: the records identify the plant through the "
                         "pendulum torque; needs the controller on the torque")
    after = scene.duration - scene.controller.start
    for name in ("detection_window", "identification_window"):
        window = getattr(a, name)
        if window > after:
            raise InputError(
                f"adaptation.{name}: {window:g} s is longer than the run after "
                f"controller.start ({after:g} s of {scene.duration:g} s)")
    if a.update_period > after:
        raise InputError(f"adaptation.update_period: {a.update_period:g} s is longer than the "
                         f"run after controller.start ({after:g} s)")


@dataclass(frozen=True)
class DesignCheck:
    """What :func:`check_design` found: the LQR gain and the poles of the LQG loop on the design
    model (regulator and filter error dynamics)."""

    gain: np.ndarray
    regulator_poles: np.ndarray
    estimator_poles: np.ndarray

    def record(self) -> dict[str, Any]:
        """The poles as ``[re, im]`` pairs and their largest magnitude, the gain."""
        def pairs(poles: np.ndarray) -> list[list[float]]:
            return [[float(p.real), float(p.imag)] for p in poles]

        return {"gain": self.gain.ravel().tolist(),
                "regulator_poles": pairs(self.regulator_poles),
                "estimator_poles": pairs(self.estimator_poles),
                "largest_pole": float(np.max(np.abs(np.concatenate(
                    [self.regulator_poles, self.estimator_poles]))))}


def check_design(scene: Scene, design: FrameModel) -> tuple[Filter, Controller, DesignCheck]:
    """The scene's estimator and controller on ``design`` and the checks of the module
    docstring; InputError naming what fails."""
    estimator = make_estimator(scene, design)
    controller = make_controller(scene, design)
    if not isinstance(estimator, Filter) or not isinstance(controller.law, LQGLaw):
        raise InputError("design check: needs a Kalman filter and an LQG law")
    lqr = controller.law.design
    period = 1.0 / scene.sensors.rate_hz
    stationary = estimator if isinstance(estimator, SteadyStateKalman) else SteadyStateKalman(
        design, scene.estimator, scene.excitation.floor, initial_physical(scene), period)
    phi = stationary.discrete(period).phi
    filter_poles = np.linalg.eigvals((np.eye(phi.shape[0]) - stationary.gain @ stationary.C)
                                     @ phi)
    check = DesignCheck(lqr.gain, np.linalg.eigvals(lqr.A - lqr.B @ lqr.gain), filter_poles)
    for name, values in (("LQR gain", lqr.gain), ("Kalman gain", stationary.gain)):
        if not np.all(np.isfinite(values)):
            raise InputError(f"design check: the {name} is not finite")
    for name, poles in (("regulator", check.regulator_poles),
                        ("estimator", check.estimator_poles)):
        radius = float(np.max(np.abs(poles)))
        if not radius < STABLE_RADIUS:
            raise InputError(f"design check: the {name}'s closed loop on the design model is "
                             f"not stable (largest pole magnitude {radius:.6g})")
    return estimator, controller, check


def design_frequencies(design: FrameModel) -> np.ndarray:
    """The design model's linearised natural frequencies [Hz], ascending."""
    A, _ = design.linearized().state_space()
    lam = np.linalg.eigvals(A)
    return np.sort(np.abs(lam[lam.imag > 0])) / (2.0 * np.pi)


@dataclass
class Handover:
    """A checked design due at ``sample`` (time ``t``): the storeys it was designed on, the
    design model, the estimator and controller built on it, and its record."""

    sample: int
    t: float
    structure: Structure
    design: FrameModel
    estimator: Filter
    controller: Controller
    record: dict[str, Any] = field(default_factory=dict)

    def apply(self, estimator: Filter, controller: Controller) -> Filter:
        """At the sample boundary: the new filter continues from ``estimator``, ``controller``
        takes the new law; the filter to step from now on."""
        self.estimator.continue_from(estimator)
        controller.take_law(self.controller)
        return self.estimator


@dataclass(frozen=True)
class DesignRequest:
    """A value of the nodes' ``design`` parameter: ``SOURCE`` or ``SOURCE@T``. SOURCE is
    :data:`SCENE_DESIGN` (the scene's design model) or a model file (``format: stillframe-mkr``
    or an identified ``.npz``: storeys with the rig's pendulum, as ``design.model: file``); T
    the sample time [s] from which it holds (none: from the next sample)."""

    source: str
    from_s: float | None

    @classmethod
    def parse(cls, value: str) -> DesignRequest:
        """InputError (text without the parameter's name) on a malformed value."""
        source, at, when = value.rpartition("@")
        if not at:
            source, when = value, ""
        if not source.strip():
            raise InputError(f"give {SCENE_DESIGN!r} or a model file, optionally @T (got "
                             f"{value!r})")
        if not when:
            return cls(source, None)
        try:
            from_s = float(when)
        except ValueError:
            raise InputError(f"@{when}: the sample time [s] the design holds from") from None
        if not (math.isfinite(from_s) and from_s >= 0):
            raise InputError(f"@{when}: a sample time >= 0")
        return cls(source, from_s)

    def design(self, scene: Scene) -> FrameModel:
        """The design model it names (InputError when the file does not load)."""
        if self.source == SCENE_DESIGN:
            return design_model(scene)
        path = resolve_model_file(self.source, "design")
        return storeys_frame(load_identified_structure(Path(path)), scene.rig)


def design_check(value: Any) -> str | None:
    """The ``design`` parameter's declared check (the form; the file and the design are
    checked when it is set, with the scene)."""
    try:
        DesignRequest.parse(value)
    except InputError as exc:
        return str(exc)
    return None


Part = TypeVar("Part")


class DesignSwitch(Generic[Part]):
    """A node's design, switched by its ``design`` parameter at a sample boundary: a request
    is checked when it is set (:func:`check_design`: refused with the reason, the running
    design stays), and its part (the estimator or the controller, ``pick``) is taken at the
    first sample stamped at or after its time. Both nodes switch at the same sample when set
    with the same ``@T``."""

    def __init__(self, scene: Scene,
                 pick: Callable[[tuple[Filter, Controller, DesignCheck]], Part]) -> None:
        self.scene = scene
        self.pick = pick
        self.pending: tuple[int, str, FrameModel, Part] | None = None
        self.current = SCENE_DESIGN
        self.taken = 0

    def request(self, value: str, last_ns: int) -> DesignCheck:
        """Check ``value`` and hold it until its sample; InputError when it cannot be taken
        (a file that does not load, a design that fails its checks, a time already past the
        node's last sample ``last_ns``)."""
        wanted = DesignRequest.parse(value)
        due_ns = last_ns + 1 if wanted.from_s is None else round(wanted.from_s * 1e9)
        if due_ns <= last_ns:
            raise InputError(f"@{wanted.from_s:g}: the node has passed that sample "
                             f"(t = {last_ns * 1e-9:g} s)")
        design = wanted.design(self.scene)
        built = check_design(self.scene, design)
        self.pending = (due_ns, wanted.source, design, self.pick(built))
        return built[2]

    def set(self, value: str, last_ns: int, log: Any) -> str | None:
        """:meth:`request` as the node's parameter callback does it, logged on ``log`` (a
        node's logger): None when taken, else the refusal's reason."""
        try:
            self.request(value, last_ns)
        except InputError as exc:
            log.warning(f"design {value!r} refused: {exc}")
            return str(exc)
        log.info(f"design {value!r} taken at its sample")
        return None

    def due(self, ns: int) -> tuple[FrameModel, Part] | None:
        """The design and part to take at the sample stamped ``ns`` (None: keep the running one)."""
        if self.pending is None or ns < self.pending[0]:
            return None
        _, self.current, design, part = self.pending
        self.pending = None
        self.taken += 1
        return design, part
