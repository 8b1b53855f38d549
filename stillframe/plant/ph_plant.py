"""The simulated rig as the frame pHDAE (``model.type: ph``,
:mod:`stillframe.dynamics.ph.scene_model`), stepped by the compiled AVF midpoint rule
(:class:`~stillframe.dynamics.ph.frame_step.CompiledFramePH`).

Same interface and sample/advance protocol as :class:`stillframe.plant.frame_plant.FramePlant`: the
actuators' [torque, floor-3 force] drive the input ports [f3, torque] held over the period; the
floor accelerations the accelerometers read are those of the index-1 form at t_k.

Process noise enters through the force ports [f1, f2, f3, torque] (a pH system takes energy only
through its ports), drawn from the same seeded stream as the FE plant's (eight normals per
period): the velocity entries of ``plant.process_noise_std`` become a force held over the period,
m σ_v / T (the impulse that gives the floor's mass, or the pendulum's inertia about the hinge,
the FE plant's velocity jump), the displacement entries a force doublet ±4 m σ_x / T² over the
two halves of the period (net impulse zero, displacement σ_x on that mass). The doublet needs an
even number of integrator steps per period; otherwise the scene is rejected naming the key.

:meth:`PHPlant.energy_sample` gives the balance of the period just ended: H at t_k and the mean
power of each port group and of the dissipation, whose integral is ΔH to round-off.
"""

from __future__ import annotations

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract.signals import Sample
from stillframe.dynamics.excitation import floor_load
from stillframe.dynamics.ph import scene_model
from stillframe.dynamics.ph.frame_step import ENERGY_TERMS
from stillframe.errors import InputError
from stillframe.plant.actuators import Actuators
from stillframe.plant.sensors import Sensors

#: the balance published per sample (:data:`stillframe.contract.topics.ENERGY_FIELDS`)
BALANCE_TERMS = ("stored", *ENERGY_TERMS)


class PHPlant:
    """The frame pHDAE with seeded sensor and process noise and limited actuators."""

    #: steps halved so far (:attr:`.protocol.Plant.subdivisions`): the AVF step never is
    subdivisions = 0

    def __init__(self, scene: Scene, period: float, substeps: int) -> None:
        self.period, self.substeps = period, substeps
        self.h = period / substeps
        fs = scene_model.scene_frame(scene)
        self.system = self.model = fs.system
        self.stepper = self.integrator = fs.stepper(self.h)
        self.load = floor_load(scene.excitation, scene.duration + period)
        self.excited_floor = scene.excitation.floor
        self.control = np.zeros(4)
        self.z = self.stepper.reduce(scene_model.initial_state(self.system, scene))
        self.sensors = Sensors(scene.sensors, np.random.default_rng(scene.sensors.seed))
        self.actuators = Actuators(scene.actuators, period)
        self.k = 0
        self._noise_forces = self._noise_scale(scene)
        self.process_rng = np.random.default_rng(scene.plant.seed)
        self.noise = np.zeros(4)
        self._offsets = (np.arange(substeps) + 0.5) * self.h
        self._fine = [np.concatenate([[0.0], self._floor_state()])]
        self._balance = np.zeros(len(ENERGY_TERMS))
        self._zero = np.zeros(4)

    def _noise_scale(self, scene: Scene) -> np.ndarray | None:
        """Force std per port [velocity part (4), displacement doublet (4)], or None."""
        std = np.asarray(scene.plant.process_noise_std, float)
        if not std.any():
            return None
        p = scene.rig.pendulum
        inertia = np.array([*scene.rig.floor_masses, p.inertia + p.mass * p.half_length**2])
        if std[:4].any() and self.substeps % 2:
            raise InputError(
                f"plant.process_noise_std: model.type ph takes displacement noise as a force "
                f"doublet over the two halves of the sample period, which needs an even number of "
                f"integrator steps per sample (have {self.substeps}); set the first four entries "
                "to 0 or halve integrator.dt")
        T = self.period
        return np.concatenate([inertia * std[4:] / T, 4.0 * inertia * std[:4] / T**2])

    def warm_up(self) -> None:
        """Load the compiled kernel now (one step on a copy of the state, thrown away)."""
        self.stepper.run(self.z.copy(), np.zeros((1, 3)), self._zero, self._zero)

    @property
    def t(self) -> float:
        """The current time t_k = k · period [s]."""
        return self.k * self.period

    def _floor_state(self) -> np.ndarray:
        r = self.stepper.readings(self.z)
        return np.concatenate([r["floors"][0], r["floor_velocities"][0]])

    def physical(self) -> np.ndarray:
        """True [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇]."""
        r = self.stepper.readings(self.z)
        return np.array([*r["floors"][0], r["phi"][0], *r["floor_velocities"][0],
                         r["phi_rate"][0]])

    def force(self, t: float) -> float:
        """The excitation force [N] on the excited floor at time ``t``; zero without a load."""
        return float(self.load(t)[self.excited_floor - 1]) if self.load else 0.0

    def _loads(self, t0: float) -> np.ndarray:
        loads = np.zeros((self.substeps, 3))
        if self.load is not None:
            loads[:, self.excited_floor - 1] = self.load.force_at(t0 + self._offsets)
        return loads

    def sample(self) -> Sample:
        """Sensor readings and ground truth at the current time t_k (the accelerations from the
        pHDAE's state, the applied control, the process noise and the load)."""
        t = self.t
        u = self.control + self.noise
        if self.load is not None:
            u[:3] += self.load(t)
        accelerations = self.stepper.floor_accelerations(self.z, u)
        readings, force = self.sensors.read(accelerations, self.physical()[3], self.force(t))
        applied = np.array([self.actuators.torque.value, self.actuators.force.value])
        return Sample(t, readings, force, truth=self.physical(), applied=applied)

    def advance(self, command: np.ndarray) -> np.ndarray:
        """Apply [torque, floor-3 force] via the actuators for one period on the compiled pHDAE
        stepper (with process noise: held over the period, plus a doublet that changes sign at its
        middle); the applied values. The energy balance of the period is kept for
        :meth:`energy_sample`."""
        applied = self.actuators.apply(command)
        self.control = np.array([0.0, 0.0, applied[1], applied[0]])
        t0 = self.t
        loads = self._loads(t0)
        scale = self._noise_forces
        if scale is None:
            parts = [(loads, self._zero)]
        else:
            draw = self.process_rng.standard_normal(8)
            held = scale[:4] * draw[4:]
            doublet = scale[4:] * draw[:4]
            half = self.substeps // 2 if doublet.any() else self.substeps
            parts = [(loads[:half], held + doublet), (loads[half:], held - doublet)]
        records, energies = [], []
        for chunk, noise in parts:
            if not len(chunk):
                continue
            self.noise = noise
            record, energy = self.stepper.run(self.z, chunk, self.control, noise, t0=t0)
            records.append(record)
            energies.append(energy)
        self._balance = np.concatenate(energies).sum(axis=0)
        times = t0 + np.arange(1, self.substeps + 1) * self.h
        self._fine.extend(np.column_stack([times, np.concatenate(records)]))
        self.k += 1
        return applied

    def energy_sample(self) -> tuple[float, np.ndarray]:
        """(t_k, [H above rest at t_k, then the mean power over the period just ended of the
        excitation, actuator and noise ports (supplied, W) and of the dissipation (W)]); the
        powers are zero before the first period. Layout: :data:`BALANCE_TERMS`."""
        return self.t, np.concatenate([[self.stepper.energy(self.z)],
                                       self._balance / self.period])

    def change_structure(self, index: int) -> None:
        """Refused: the pHDAE's constraints and energy ports belong to one structure (a scene
        with events and ``model.type: ph`` is refused at load)."""
        raise InputError(f"events[{index}]: the ph plant cannot change its structure while it "
                         "runs; use model.type: lumped or fe")

    def truth_history(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Times, floor displacements (N×3) and velocities (N×3) at every integrator step, the
        initial state first."""
        r = np.asarray(self._fine)
        return r[:, 0], r[:, 1:4], r[:, 4:7]
