"""The simulated rig, one sample period at a time: model + excitation + actuators + sensors.

Per period k the caller takes :meth:`Plant.sample` at t_k (readings with the command of the
previous period still applied) and then :meth:`Plant.advance` with the new command, which the
actuators limit and hold over [t_k, t_k+1) while the scene's integrator takes its steps. The
plant is the scene's nonlinear model (``plant.model: scene``) or the thesis's LQG plant, the linear
second-order model of an identified structure with the linearised pendulum (``plant.model: file``,
eq. 5.199–5.207). Process noise (eq. 5.215) is added to the physical state once per period. Ground
truth is kept at every integrator step for the evaluation.

A scene's ``events`` (:mod:`stillframe.config.events`) change the structure of the lumped and FE
plants while they run: the loop's step calls :meth:`FramePlant.change_structure` at the sample
boundary of each event, and the plant goes on from its state with the model of the changed
structure (built at load).
"""

from __future__ import annotations

import numpy as np

from stillframe.config.scene import Scene, changed_scene, sample_grid
from stillframe.contract.signals import Sample
from stillframe.design.identified import frame_for
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.integrators import (
    Subdivision,
    check_finite,
    integrate,
    make_integrator,
    non_finite,
)
from stillframe.dynamics.kernels import CompiledFrame, compiles
from stillframe.dynamics.models import FrameModel, build_model
from stillframe.dynamics.simulation import initial_state
from stillframe.dynamics.systems import LinearSystem, MechanicalSystem
from stillframe.errors import InputError, IntegrationError
from stillframe.plant.actuators import Actuators
from stillframe.plant.linear_period import LinearPeriod, make_linear_period
from stillframe.plant.ph_plant import PHPlant
from stillframe.plant.protocol import Plant
from stillframe.plant.sensors import Sensors

__all__ = ["FramePlant", "make_plant"]

#: the truth kept at every substep, in the physical state: floor displacements and velocities
RECORDED = np.array([0, 1, 2, 4, 5, 6])


def make_plant(scene: Scene) -> Plant:
    """The scene's plant: the frame pHDAE for ``model.type: ph`` (``plant.model: scene``),
    else :class:`FramePlant`."""
    if scene.model.type == "ph" and scene.plant.model == "scene":
        return PHPlant(scene, *sample_grid(scene))
    return FramePlant(scene)


def _changed_model(scene: Scene, index: int) -> FrameModel:
    """The model of ``scene``'s structure after its event ``index``; InputError naming the
    event where the model refuses it (damping that turns negative, say)."""
    try:
        return build_model(changed_scene(scene, index + 1))
    except InputError as exc:
        raise InputError(f"events[{index}]: the structure after it: {exc}") from None


class FramePlant:
    """Scene-driven plant with seeded sensor and process noise."""

    def __init__(self, scene: Scene) -> None:
        self.period, self.substeps = sample_grid(scene)
        self.h = self.period / self.substeps
        self.load = floor_load(scene.excitation, scene.duration + self.period)
        self.excited_floor = scene.excitation.floor
        self.linear_plant = scene.plant.model == "file"
        self.discretization = scene.plant.discretization
        self.subdivision = Subdivision.of(scene.integrator)
        self.method_name = scene.integrator.method
        if self.discretization == "zoh" and not self.linear_plant:
            raise InputError("plant.discretization: zoh needs the linear plant "
                             "(plant.model: file)")
        #: integrator steps halved on the structures simulated before the current one
        self.halved_before = 0
        model = frame_for(scene.plant.model, scene.plant.file, scene, "plant.file")
        self.take(model, self.compiled_for(model), np.zeros(4))
        #: the model of the structure after each of the scene's events with its compiled
        #: kernels, built at load (a change the model refuses is an error before the run, and
        #: the sample of the event does not wait for them) and taken at the event
        self.changed = [(changed, self.compiled_for(changed))
                        for changed in (_changed_model(scene, i)
                                        for i in range(len(scene.events)))]
        self.x = initial_state(model, scene.initial)
        #: how a substep is taken: the integrator's name, or zoh
        self.method = "zoh" if self.discretization == "zoh" else self.integrator.name
        self.process_std = np.asarray(scene.plant.process_noise_std, dtype=float)
        self.process_rng = np.random.default_rng(scene.plant.seed)
        self.sensors = Sensors(scene.sensors, np.random.default_rng(scene.sensors.seed))
        self.actuators = Actuators(scene.actuators, self.period)
        self.k = 0
        n_steps = round(scene.duration / self.period) * self.substeps + 1
        self._fine = np.empty((n_steps, 7))
        self._rows = 0
        self._record(0.0, self.x)

    def compiled_for(self, model: FrameModel) -> CompiledFrame | None:
        """``model`` prepared for the compiled kernels, where they handle the plant: the
        nonlinear model under a load and integrator they take (None: the integrator's steps)."""
        if self.linear_plant or not compiles(self.load, self.method_name):
            return None
        return CompiledFrame(model, self.subdivision)

    def take(self, model: FrameModel, compiled: CompiledFrame | None,
             control: np.ndarray) -> None:
        """Simulate ``model`` (on ``compiled``, its kernels) from now on, with ``control`` = u
        held: everything else derived from a model (the system, a fresh integrator, the linear
        period) is built here, once per structure."""
        self.model = model
        n = model.n_dof
        self.n_dof = n
        picks = [*model.floor_index, model.phi_index]
        self.physical_index = np.array([*picks, *(n + i for i in picks)])
        self._recorded_index = self.physical_index[RECORDED]
        self._substep_times = np.arange(1, self.substeps + 1) * self.h   # after t_k
        self.system = (LinearSystem(model.linearized(), self.load) if self.linear_plant
                       else MechanicalSystem(model, self.load))
        self.system.control = control
        self.integrator = make_integrator(self.method_name, self.subdivision)
        self.linear = self._linear_period()
        #: the nonlinear model's substeps on the compiled kernels where they handle its load
        self.compiled = compiled
        self._acceleration_rows = None
        if isinstance(self.system, LinearSystem):
            rows = [n + i for i in model.floor_index]
            E, A, B = self.system.E, self.system.A, self.system.B
            self._acceleration_rows = np.linalg.solve(E, np.hstack([A, B]))[rows]
            self._acceleration_input = np.zeros(self._acceleration_rows.shape[1])

    def change_structure(self, index: int) -> None:
        """From now on the structure after the scene's event ``index``: its model taken
        (:meth:`take`) with the state as it is. The state's DOFs are the same for every
        structure of one scene (the same floors and column nodes), so positions and velocities
        carry over as they are: a mass added is bolted on at rest relative to its floor, a
        stiffness or damping changes with the deformation as it is."""
        self.halved_before = self.subdivisions
        self.take(*self.changed[index], self.system.control)

    def _linear_period(self) -> LinearPeriod | None:
        """The period as one matrix product (:mod:`stillframe.plant.linear_period`) for a
        linear plant stepped by the midpoint rule or exactly; None: the integrator's steps."""
        discretization = self.discretization
        if not isinstance(self.system, LinearSystem) or (
                discretization == "substeps" and self.integrator.name != "midpoint"):
            return None
        recorded = self.physical_index[RECORDED]
        return make_linear_period(self.system, self.load, discretization, self.period,
                                  self.substeps, recorded)

    @property
    def subdivisions(self) -> int:
        """How many steps were halved so far (:mod:`stillframe.dynamics.integrators`), over
        every structure simulated."""
        return self.halved_before + (self.compiled or self.integrator).subdivisions

    @property
    def t(self) -> float:
        """The current time t_k = k · period [s]."""
        return self.k * self.period

    def physical(self) -> np.ndarray:
        """True [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇]."""
        return self.x[self.physical_index].copy()

    def warm_up(self) -> None:
        """Load (or compile) the compiled kernels now, with one substep on a copy of the state
        that is thrown away: the first ``advance`` otherwise takes them in, about 0.2 s, inside
        the loop (a late first sample in real time). The plant's state does not change. The
        kernels of the structures after the scene's events too (the implicit midpoint rule's
        banded step matrix is factored on the first step: 0.5 s on FE 40), their throwaway
        substep not counted."""
        if self.compiled is not None:
            self.compiled.run(self.integrator.name, self.x.copy(), self.h, 1, load=self.load,
                              control=self.system.control, t0=self.t)
        for _, compiled in self.changed:
            if compiled is not None:
                compiled.run(self.integrator.name, self.x.copy(), self.h, 1, load=self.load,
                             control=self.system.control, t0=self.t)
                compiled.subdivisions = 0

    def sample(self) -> Sample:
        """Sensor readings and ground truth at the current time t_k."""
        t = self.t
        loads = self.load(t) if self.load else None
        if self._acceleration_rows is not None:  # linear: E⁻¹[A B] rows, formed once
            z, n = self._acceleration_input, self.x.size
            z[:n] = self.x
            z[n:] = self.system.control
            if loads is not None:
                z[n : n + 3] += loads
            accelerations = self._acceleration_rows @ z
        else:
            accelerations = self.system.derivative(t, self.x)[self.n_dof:][self.model.floor_index]
        force = float(loads[self.excited_floor - 1]) if loads is not None else 0.0
        readings, force = self.sensors.read(accelerations, self.x[self.model.phi_index], force)
        applied = np.array([self.actuators.torque.value, self.actuators.force.value])
        return Sample(t, readings, force, truth=self.physical(), applied=applied)

    def advance(self, command: np.ndarray) -> np.ndarray:
        """Apply [torque, floor-3 force] via the actuators for one period; the applied values."""
        applied = self.actuators.apply(command)
        self.system.control = np.array([0.0, 0.0, applied[1], applied[0]])
        t0 = self.t
        if self.linear is not None:
            self._advance_linear(self.linear, t0)
            return applied
        try:
            if self.compiled is not None:
                states = self.compiled.run(self.integrator.name, self.x, self.h, self.substeps,
                                           load=self.load, control=self.system.control, t0=t0)
                self._record_period(t0, states[1:, self.physical_index[RECORDED]])
                self.x = states[-1].copy()
            else:
                self.x = integrate(self.system, self.x, self.h, self.substeps, self.integrator,
                                   t0, observer=self._observe)
        except (ValueError, OverflowError) as exc:  # math.sin(inf) and the like
            if isinstance(exc, IntegrationError):
                raise
            raise IntegrationError(
                f"integrator.dt: the state left the finite range at t ≈ {t0:.6g} s (the command "
                f"{applied} drove it away; limit the actuators or reduce integrator.dt)"
            ) from None
        self._add_process_noise()
        check_finite(self.x, t0 + self.period, self.h, self.integrator.name)
        self.k += 1
        return applied

    def _advance_linear(self, linear: LinearPeriod, t0: float) -> None:
        """``advance`` of a linear plant: the substeps as one product, recorded alike."""
        recorded, x = linear.step(self.x, self.k, self.system.control)
        if not np.all(np.isfinite(x)):
            first = int(np.argmax(~np.isfinite(recorded).all(axis=1)))
            raise non_finite(t0 + (first + 1) * self.h, self.h, self.method)
        self._record_period(t0, recorded)
        self.x = x
        self._add_process_noise()
        self.k += 1

    def _record_period(self, t0: float, recorded: np.ndarray) -> None:
        """The truth after each substep of the period from t0 (rows of ``recorded``)."""
        s, rows = self.substeps, self._rows
        if rows + s > len(self._fine):
            self._fine = np.vstack([self._fine, np.empty_like(self._fine)])
        fine = self._fine[rows : rows + s]
        fine[:, 0] = t0 + self._substep_times
        fine[:, 1:] = recorded
        self._rows = rows + s

    def _add_process_noise(self) -> None:
        """Eq. 5.215, once per period; the last recorded row follows."""
        if self.process_std.any():
            self.x[self.physical_index] += self.process_std * self.process_rng.standard_normal(8)
            self._fine[self._rows - 1, 1:] = self.x[self._recorded_index]

    def _observe(self, k: int, t: float, x: np.ndarray) -> None:
        if k > 0:
            self._record(t, x)

    def _record(self, t: float, x: np.ndarray) -> None:
        if self._rows == len(self._fine):
            self._fine = np.vstack([self._fine, np.empty_like(self._fine)])
        p = x[self.physical_index]
        self._fine[self._rows] = (t, p[0], p[1], p[2], p[4], p[5], p[6])
        self._rows += 1

    def truth_history(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Times, floor displacements (N×3) and velocities (N×3) at every integrator step."""
        r = self._fine[: self._rows]
        return r[:, 0], r[:, 1:4], r[:, 4:7]
