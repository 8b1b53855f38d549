"""The structure identified from a closed loop's own records: the excitation force, the hinge
torque the loop applied and the sensors (docs/adaptation.md).

Records at each sample t_k (what the estimator has): the load cell (the excitation held over
[t_k, t_k+1)), the torque the actuator applied over [t_k−1, t_k) (the encoder's ``effort``), the
three floor accelerations and φ. The loop's torque feeds back the outputs, so the records are
closed-loop data; the method is the direct approach (Ljung, *System Identification*, 2nd ed.,
§13.4; Forssell & Ljung 1999, *Automatica* 35, "Closed-loop identification revisited"): both
inputs measured and identified as inputs, OKID + ERA/DC (:func:`.pipeline.identify`) at order 8
(the three storeys' modes and the pendulum's). It is consistent when the torque holds a part the
outputs do not explain: the controller's probe (``adaptation.probe_std``), a small white torque
added to its command. Without one the torque is a linear function of past outputs (an LTI
controller of lower order than OKID's observer), the regression is singular, and OKID's Markov
parameters diverge or its modes are spurious (docs/adaptation.md shows both). The
prediction-error refinement is not used (``refine=False``): on main it is not made for
closed-loop data.

The torque column: the acceleration at t_k is read with the torque of [t_k−1, t_k) applied and
the force of [t_k, t_k+1), so with the inputs as recorded the realization is
(A, [A⁻¹ B_f, B_τ], C A, ·) of the sampled plant (A, [B_f, B_τ], C): the same A and transfer
functions, the torque's one sample early. MKR needs the pair (B, C) of one realization, so the
torque column is mapped back by A⁻¹ (:func:`torque_recorded_late`).

MKR (thesis §3.7) on four DOFs q = [x1, x2, x3, φ]: the accelerometers on DOFs 0–2, the force
on DOF 0 (co-located with floor 1's accelerometer), the torque on DOF 3 (φ's generalized
force); φ's own sensor helps the identification and is left out of MKR (it measures an angle,
not an acceleration: eq. 3.228 needs one kind). Linearised, the rig is M q̈ + R q̇ + K q = B u
with M = [[M_s + m4 e3 e3ᵀ, m4 L4 e3], [m4 L4 e3ᵀ, J]] (:mod:`stillframe.dynamics.models.frame`),
so the structure is M_s = M[:3, :3] − m4 e3 e3ᵀ (m4 the rig's) and K_s = K[:3, :3]; the design
model adds the rig's pendulum again (eqs. 5.200–5.205), as for the thesis's identified
structure (:mod:`.structure_model`). The damping is R_s = α M_s + β K_s with α, β fitted to the
three identified storey modes (MKR's own R from noisy data is unreliable; eq. 3.242); the
pendulum's mode, whose shape is most φ, is left out of the fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stillframe.config.scene import Rig
from stillframe.errors import IdentificationError
from stillframe.identification.damping import fit_proportional_damping, proportional_damping_matrix
from stillframe.identification.mkr import PhysicalModel, mkr
from stillframe.identification.modal import ModalTable
from stillframe.identification.pipeline import Identification, identify

Array = NDArray[np.float64]

ORDER = 8
"""Three storey modes and the pendulum's."""
SENSOR_DOFS = (0, 1, 2)
ACTUATOR_DOFS = (0, 3)
INPUT_NAMES = ("load cell force", "applied torque")
OUTPUT_NAMES = ("a1", "a2", "a3", "phi")
METHOD = "okid-eradc"


@dataclass(frozen=True)
class LoopStructure:
    """The identification, MKR's four-DOF result and the storeys' structure for a design."""

    ident: Identification
    raw: PhysicalModel
    """M, K, R on [x1, x2, x3, φ] (MKR, eqs. 3.232–3.241)."""
    structure: PhysicalModel
    """The storeys: M_s, K_s and the Rayleigh R_s (module docstring)."""
    rayleigh_alpha: float
    rayleigh_beta: float
    pendulum_mode: int
    """The index (ascending frequency) of the mode left out of the damping fit."""


def identify_loop_modes(u: Array, y: Array, dt: float) -> Identification:
    """The direct identification of the module docstring: ``u (N, 2)`` = [force, applied
    torque], ``y (N, 4)`` = [a1, a2, a3, φ]; InputError or IdentificationError as
    :func:`.pipeline.identify` raises them."""
    return identify(u, y, dt, METHOD, ORDER, refine=False, input_names=INPUT_NAMES,
                    output_names=OUTPUT_NAMES)


def torque_recorded_late(A: Array, B: Array) -> Array:
    """B with its torque column (the second) mapped by A⁻¹ (module docstring)."""
    out = np.array(B, dtype=float)
    out[:, 1] = np.linalg.solve(A, out[:, 1])
    return out


def pendulum_mode(modes: ModalTable, half_length: float) -> int:
    """The mode whose shape is most the pendulum's: the largest ratio of the pendulum's tip
    displacement L4 |φ| to the floors' |a| / ω² (outputs [a1, a2, a3, φ])."""
    shapes = np.abs(modes.shapes)
    floors = np.linalg.norm(shapes[:3], axis=0) / modes.omega**2
    return int(np.argmax(half_length * shapes[3] / np.maximum(floors, np.finfo(float).tiny)))


def identify_loop_structure(u: Array, y: Array, dt: float, rig: Rig) -> LoopStructure:
    """:func:`identify_loop_modes`, MKR on four DOFs and the storeys' structure (module
    docstring); IdentificationError when MKR's result is not a structure (a storey mass or
    stiffness matrix not positive definite, a negative damping fit)."""
    ident = identify_loop_modes(u, y, dt)
    A, C = ident.A, ident.C
    raw = mkr(A, torque_recorded_late(A, ident.B), C[:3], dt, SENSOR_DOFS, ACTUATOR_DOFS,
              "acceleration")
    mass = raw.M[:3, :3].copy()
    mass[2, 2] -= rig.pendulum.mass
    stiffness = raw.K[:3, :3].copy()
    for name, matrix in (("mass", mass), ("stiffness", stiffness)):
        if np.min(np.linalg.eigvalsh(matrix)) <= 0:
            raise IdentificationError(
                f"MKR's storey {name} matrix (the floors' block, the rig's pendulum taken off "
                f"floor 3) is not positive definite: the records do not identify the structure")
    modes = ident.modes
    order = np.argsort(modes.frequency_hz)
    pendulum = int(np.flatnonzero(order == pendulum_mode(modes, rig.pendulum.half_length))[0])
    storeys = np.delete(order, pendulum)
    alpha, beta = fit_proportional_damping(modes.omega[storeys], modes.damping_ratio[storeys])
    damping = proportional_damping_matrix(mass, stiffness, alpha, beta)
    if np.min(np.linalg.eigvalsh(damping)) < 0:
        raise IdentificationError(
            f"the Rayleigh damping fitted to the storey modes (alpha {alpha:.3g}, beta "
            f"{beta:.3g}) is not positive semi-definite on the identified structure")
    return LoopStructure(ident, raw, PhysicalModel(mass, stiffness, damping), alpha, beta,
                         pendulum)
