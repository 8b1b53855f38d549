"""Passivity-based control through the pendulum's torque port (seed 000 §7: control by
interconnection through the pH ports).

The hinge torque u and the relative angular velocity y = φ̇ are a collocated power port of every
plant model: dH/dt ≤ y u. The law

    u = −k_p φ − k_d φ̇                       (energy shaping + damping injection)

makes the closed loop a port-Hamiltonian system with the shaped storage H_d = H + ½ k_p φ²
(still positive definite for k_p ≥ 0) and dissipation increased by k_d φ̇² ≥ 0, so
dH_d/dt ≤ −k_d φ̇² + (floor forces)·(floor velocities): stable for every passive plant (lumped,
FE, modal, pH) with the same gains — no model enters the law. Plain numpy, no middleware.
"""

from __future__ import annotations

import numpy as np

from stillframe.errors import InputError


class PassivityLaw:
    """u = −k_p φ − k_d φ̇ on the design state z = [q, q̇] with φ at ``phi_index``."""

    def __init__(self, n_dof: int, phi_index: int, stiffness: float, damping: float) -> None:
        if stiffness < 0 or damping <= 0:
            raise InputError("controller: passivity needs shaping_stiffness >= 0 and "
                             "injection_damping > 0")
        self.angle, self.rate = phi_index, n_dof + phi_index
        self.kp, self.kd = stiffness, damping

    def __call__(self, z: np.ndarray, force: float) -> tuple[float, bool]:
        return -self.kp * float(z[self.angle]) - self.kd * float(z[self.rate]), False
