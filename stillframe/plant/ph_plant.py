"""The simulated rig as the frame pHDAE (``model.type: ph``,
:mod:`stillframe.dynamics.ph.scene_model`).

Same interface and sample/advance protocol as :class:`stillframe.plant.frame_plant.Plant`: the
actuators'
[torque, floor-3 force] drive the input ports [f3, torque] held over the period while the AVF
midpoint integrator takes its steps; the floor accelerations the accelerometers read are the
exact ones of the index-1 form at t_k. Process noise is not supported (the pH state is not the
8-vector it would be added to).
"""

from __future__ import annotations

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract.signals import Sample
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.ph import frame, scene_model
from stillframe.dynamics.ph.integrator import MidpointDAE
from stillframe.dynamics.ph.reference import index1_rhs
from stillframe.errors import InputError
from stillframe.plant.actuators import Actuators
from stillframe.plant.sensors import Sensors


class PHPlant:
    """The frame pHDAE with seeded sensor noise and limited actuators."""

    def __init__(self, scene: Scene, period: float, substeps: int) -> None:
        if any(scene.plant.process_noise_std):
            raise InputError("plant.process_noise_std: model.type ph takes no process noise")
        self.period, self.substeps = period, substeps
        self.h = period / substeps
        self.system = scene_model.scene_system(scene)
        self.load = floor_load(scene.excitation, scene.duration + period)
        self.excited_floor = scene.excitation.floor
        self.control = np.zeros(4)
        self.integrator = MidpointDAE(self.system, self.h, self.inputs)
        self.model = self.system
        self._rates = index1_rhs(self.system, self.inputs)
        self.x = scene_model.initial_state(self.system, scene)
        self.lam = np.zeros(self.system.n_constraints)
        self._previous: np.ndarray | None = None
        self.sensors = Sensors(scene.sensors, np.random.default_rng(scene.sensors.seed))
        self.actuators = Actuators(scene.actuators, period)
        self.k = 0
        self._fine: list[tuple[float, ...]] = []
        self._record(0.0)

    def warm_up(self) -> None:
        """Nothing to load before the loop (:meth:`Plant.warm_up`): the pHDAE steps in numpy."""

    def inputs(self, t: float) -> np.ndarray:
        u = self.control.copy()
        if self.load is not None:
            u[:3] += self.load(t)
        return u

    @property
    def t(self) -> float:
        return self.k * self.period

    def _reading(self) -> dict:
        return frame.sensors(self.system, self.x)

    def physical(self) -> np.ndarray:
        """True [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇]."""
        r = self._reading()
        return np.array([*r["floors"], r["phi"], *r["floor_velocities"], r["phi_rate"]])

    def force(self, t: float) -> float:
        return float(self.load(t)[self.excited_floor - 1]) if self.load else 0.0

    def sample(self) -> Sample:
        t = self.t
        rates = self._rates(t, self.x)[self.system.n_q:2 * self.system.n_q]
        accelerations = np.array([rates[self.system.q_slices[f"floor{i}"].start]
                                  for i in (1, 2, 3)])
        readings, force = self.sensors.read(accelerations, self._reading()["phi"], self.force(t))
        applied = np.array([self.actuators.torque.value, self.actuators.force.value])
        return Sample(t, readings, force, truth=self.physical(), applied=applied)

    def advance(self, command: np.ndarray) -> np.ndarray:
        applied = self.actuators.apply(command)
        self.control = np.array([0.0, 0.0, applied[1], applied[0]])
        t0 = self.t
        for j in range(self.substeps):
            guess = None if self._previous is None else 2 * self.x - self._previous
            self._previous = self.x
            self.x, self.lam = self.integrator.step(self.x, self.lam, t0 + j * self.h, guess)
            self._record(t0 + (j + 1) * self.h)
        self.k += 1
        return applied

    def _record(self, t: float) -> None:
        r = self._reading()
        self._fine.append((t, *r["floors"], *r["floor_velocities"]))

    def truth_history(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r = np.asarray(self._fine)
        return r[:, 0], r[:, 1:4], r[:, 4:7]
