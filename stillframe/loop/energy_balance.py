"""The pH plant's energy balance on a topic, and the live passivity check of the passivity
controller (docs/port-hamiltonian.md, "The energy balance on a topic").

Per sample t_k the pH plant (:meth:`stillframe.plant.ph_plant.PHPlant.energy_sample`) gives the
stored energy H(t_k) above rest and the mean power of the period just ended through each port
group (excitation, actuator, process noise) and into the dissipation; sim_node publishes them on
``energy_balance`` (:data:`stillframe.contract.topics.ENERGY_BALANCE`).

With ``controller.type: passivity`` (u = −k_p φ − k_d φ̇ on the torque port) the controller is a
passive system with storage H_c = ½ k_p φ²: from its start t_s, the energy it supplies through the
actuator port can never exceed the storage it released,

    W_act(t) = Σ T P_actuator ≤ H_c(φ(t_s)) − H_c(φ(t)),

(the passivity inequality of the controller; with k_p = 0 it may only take energy out). The
sampled law, an estimator's error or an actuation delay can break it; :class:`PassivityCheck`
evaluates it every sample and reports in ``/diagnostics`` (WARN, with the excess and the time it
was first exceeded) when it does.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract import topics
from stillframe.contract.codecs import EnergyMessage
from stillframe.middleware.taps import TappedPublisher

#: relative tolerance on the passivity inequality (of the largest stored energy seen): round-off
#: of the balance, far below any physical excess
TOLERANCE = 1e-9


class PassivityCheck:
    """W_act(t) ≤ ½k_p(φ(t_s)² − φ(t)²) for ``controller.type: passivity``, sample by sample."""

    def __init__(self, scene: Scene, period: float) -> None:
        c = scene.controller
        self.active = c.type == "passivity"
        self.kp, self.start, self.period = c.shaping_stiffness, c.start, period
        self.supplied = 0.0
        self.allowed = 0.0
        self.storage_at_start: float | None = None
        self.excess_max = 0.0
        self.violations = 0
        self.first_violation_t: float | None = None
        self.largest_energy = 0.0

    def update(self, t: float, balance: np.ndarray, phi: float) -> None:
        """Sample t_k: ``balance`` = [H, P_excitation, P_actuator, P_noise, P_dissipated] of the
        period ending at t_k, φ(t_k)."""
        self.largest_energy = max(self.largest_energy, abs(float(balance[0])))
        if not self.active:
            return
        storage = 0.5 * self.kp * phi * phi
        if self.storage_at_start is None:   # the first command applies over [t_s, t_s + T]
            if t >= self.start:
                self.storage_at_start = storage
            return
        self.supplied += self.period * float(balance[2])
        self.allowed = self.storage_at_start - storage
        excess = self.supplied - self.allowed
        if excess > TOLERANCE * self.largest_energy + 1e-15:
            self.violations += 1
            self.excess_max = max(self.excess_max, excess)
            if self.first_violation_t is None:
                self.first_violation_t = t

    def values(self) -> dict[str, Any]:
        """The check's figures for ``/diagnostics`` once it is active: the energy the controller
        supplied and the energy its storage allowed [J], the largest excess [J] and the violations;
        empty otherwise."""
        if not self.active:
            return {}
        return {"controller_energy_J": self.supplied, "controller_energy_allowed_J": self.allowed,
                "passivity_excess_J": self.excess_max, "passivity_violations": self.violations}

    def message(self) -> str:
        """One line on the violations (the largest excess, how many samples, the first time), ""
        without any."""
        if not self.violations:
            return ""
        return (f"passivity: the controller supplied up to {self.excess_max:.3g} J more than its "
                f"storage ½k_pφ² released ({self.violations} samples, first at "
                f"t = {self.first_violation_t:.6g} s)")


class EnergyLedger:
    """The pH plant's balance at each sample and the passivity check over it: what sim_node
    publishes and reports, and what the one-process loop reports alike."""

    def __init__(self, plant: Any, scene: Scene) -> None:
        self.plant = plant
        self.check = PassivityCheck(scene, plant.period)
        self.t = 0.0
        self.last = np.zeros(len(topics.ENERGY_FIELDS) - 1)

    @classmethod
    def of(cls, plant: Any, scene: Scene) -> EnergyLedger | None:
        """The ledger of a plant that keeps its energy balance, else None."""
        return cls(plant, scene) if hasattr(plant, "energy_sample") else None

    def update(self, phi: float) -> None:
        """Sample t_k's balance (call after ``plant.sample()``), checked."""
        self.t, self.last = self.plant.energy_sample()
        self.check.update(self.t, self.last, phi)

    def values(self) -> dict[str, Any]:
        """The energy stored above rest at the last sample [J] and the passivity check's figures
        (:meth:`PassivityCheck.values`)."""
        return {"energy_stored_J": float(self.last[0]), **self.check.values()}


class EnergyTopic:
    """sim_node's ``energy_balance`` publisher over an :class:`EnergyLedger` (pH plant only)."""

    def __init__(self, node: Any, ledger: EnergyLedger, qos: Any) -> None:
        spec = topics.ENERGY_BALANCE
        self.ledger = ledger
        self.check = ledger.check
        self.publisher = TappedPublisher(node, spec.type_name, spec.name, qos)
        self.message = EnergyMessage()

    @classmethod
    def of(cls, node: Any, plant: Any, scene: Scene, qos: Any) -> EnergyTopic | None:
        """The topic for a plant that keeps its energy balance, else None."""
        ledger = EnergyLedger.of(plant, scene)
        return None if ledger is None else cls(node, ledger, qos)

    def publish(self, phi: float) -> None:
        """Sample t_k's balance, checked and published (call after ``plant.sample()``)."""
        self.ledger.update(phi)
        self.publisher.publish(self.message.cdr(self.ledger.t, self.ledger.last))

    def values(self) -> dict[str, Any]:
        """Its ledger's figures (:meth:`EnergyLedger.values`)."""
        return self.ledger.values()
