"""Extended Udwadia–Kalaba control (thesis §5.7): a virtual constraint on floor 3 plus the
under-actuation constraints "every other DOF obeys its own equation of motion".

With the actuator on one DOF (input column b), M(q) q̈ = Q(q, q̇, u₀) + b u and the constraint
ẍ3 = a_des have the unique solution u = (a_des − a_free,3) / g with a_free = M⁻¹Q(q, q̇, u₀) (the
motion without control, the measured excitation in u₀) and g = (M⁻¹ b)₃, the floor-3
acceleration per unit command. For the lumped model this is eq. 5.246 (actuator on the pendulum,
variant 1) and eq. 5.251 (force on floor 3, variant 2); the same formula serves every
structural model. a_des = 0 is the thesis's constraint (eq. 5.240); ``hold_damping`` kd and
``hold_stiffness`` kp give a_des = −kd ẋ3 − kp x3 (a Baumgarte-type correction that also pulls
the floor back when the sampled control lets it drift).

Singularity of variant 1: on the lumped model g = −m4 L4 cos φ / ((m3 + m4) J − (m4 L4 cos φ)²),
zero when the pendulum is horizontal (sin θ → 0 in the thesis's angle), where eq. 5.246 divides
by zero. Here the command is the singularity-robust (damped least-squares) inverse
u = g e / (g² + λ²), e = a_des − a_free,3, λ = ``singular_margin`` · |g at rest|: equal to the
exact law up to the factor g²/(g² + λ²) (0.9996 at rest for the default margin 0.02), bounded by
|e| / (2λ) everywhere, and zero at the singular configuration itself; the command is flagged
``singular`` while |g| < λ. Variant 2 has g = 1/(m3 + m4 − (m4 L4 cos φ)²/J) > 0 for every φ and
uses the exact inverse.
"""

from __future__ import annotations

import numpy as np

from stillframe.contract.signals import full_inputs
from stillframe.dynamics.models import FrameModel

ACTUATORS = {"pendulum": 0, "floor": 1}  # index in [torque, floor-3 force]


class EUKLaw:
    """Command on the pendulum (variant 1) or on floor 3 (variant 2) holding ẍ3 = a_des."""

    def __init__(self, model: FrameModel, actuator: str, excited_floor: int,
                 hold_stiffness: float = 0.0, hold_damping: float = 0.0,
                 singular_margin: float = 0.02) -> None:
        self.model = model
        self.actuator = actuator
        self.excited_floor = excited_floor
        self.kp, self.kd = hold_stiffness, hold_damping
        self.column = np.zeros(model.n_dof)
        self.column[model.phi_index if actuator == "pendulum" else model.i3] = 1.0
        rest = abs(self.gain(np.zeros(model.n_dof)))
        self.damping = singular_margin * rest if actuator == "pendulum" else 0.0

    def gain(self, q: np.ndarray) -> float:
        """g = (M(q)⁻¹ b)₃: floor-3 acceleration per unit command."""
        return float(np.linalg.solve(self.model.mass_matrix(q), self.column)[self.model.i3])

    def __call__(self, z: np.ndarray, force: float) -> tuple[float, bool]:
        """The command and whether the configuration is (near-)singular."""
        m = self.model
        q, v = z[: m.n_dof], z[m.n_dof :]
        a_free = m.accelerations(q, v, full_inputs(np.zeros(2), force, self.excited_floor))
        error = -self.kd * v[m.i3] - self.kp * q[m.i3] - a_free[m.i3]
        g = self.gain(q)
        lam = self.damping
        return g * error / (g * g + lam * lam), abs(g) < lam
