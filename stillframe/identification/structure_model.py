"""The identified floors-only structure for the LQG design model (thesis §5.5 → §5.6).

From a force on floor 1 and the three floor accelerations: OKID + ERA/DC at order 6 (three
structural modes), MKR (eqs. 3.232–3.241) for M and K, and the damping as R = αM + βK with α, β
fitted to the identified modes (eqs. 3.208–3.213, 3.242; MKR's own R from noisy data is
unreliable, as the thesis notes). The rig carries its pendulum during the test, so the identified
floor-3 mass includes the pendulum's apparent mass; the design model adds the pendulum to the
structure again (eqs. 5.200–5.205), so that mass is taken off floor 3 first:
:func:`pendulum_apparent_mass`.

The scale of M, K, R is that of the input: the discrete model (and MKR's ``B_c = (A − I)⁻¹ A_c B``,
eq. 3.43) assumes a force held over each sample period. The load cell then reads exactly the force
applied over the next period. A blow shorter than a period is not measured by its samples (a
half-sine one period wide, sampled at its peak, reads π/2 times its impulse per period and lies half
a period early): :func:`unresolved_pulse` detects such inputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from stillframe.config.schema import Section
from stillframe.identification.damping import fit_proportional_damping, proportional_damping_matrix
from stillframe.identification.mkr import PhysicalModel, mkr
from stillframe.identification.model_file import model_from_identification, save_model
from stillframe.identification.pipeline import Identification, identify

Array = NDArray[np.float64]
ORDER = 6
SENSOR_DOFS = (0, 1, 2)
ACTUATOR_DOFS = (0,)
#: an input sample holding more than this share of the record's energy is a lone pulse
PULSE_ENERGY_SHARE = 0.5


def pendulum_apparent_mass(rig: Section) -> float:
    """The horizontal mass the hanging pendulum adds to its floor well above its own mode:
    ``m4 I / (I + m4 L4²)`` (from ``J φ̈ = −m4 L4 ẍ3`` and the force ``m4 (ẍ3 + L4 φ̈)`` at the
    hinge of eq. 5.57 without gravity and hinge damping; I about the centre of mass)."""
    p = rig.pendulum
    return p.mass * p.inertia / (p.inertia + p.mass * p.half_length**2)


def unresolved_pulse(u: Array) -> str | None:
    """A warning when one input sample holds more than half of an input's energy (a blow shorter
    than the sampling resolves), else None."""
    u = np.atleast_2d(np.asarray(u, dtype=float).T).T
    energy = np.sum(u**2, axis=0)
    share = np.max(u**2, axis=0) / np.where(energy > 0, energy, 1.0)
    if np.any(share > PULSE_ENERGY_SHARE):
        return ("the input is a pulse within one sample: its sampled value need not be its "
                "impulse per sample period (zero-order hold), so the scale of B and of M, K, R "
                "is not trustworthy; excite with a force held over each sample period (white "
                "noise at the sampling rate, as `stillframe experiment` does)")
    return None


@dataclass(frozen=True)
class IdentifiedStructure:
    """The identification, MKR's raw result, and the structure for the design model."""

    ident: Identification
    raw: PhysicalModel
    structure: PhysicalModel
    rayleigh_alpha: float
    rayleigh_beta: float
    pendulum_mass: float
    warnings: tuple[str, ...]


def identify_structure(u: Array, y: Array, dt: float, rig: Section) -> IdentifiedStructure:
    """OKID + ERA/DC (order 6), MKR and the design structure from a floor-1 force ``u (N, 1)``
    and floor accelerations ``y (N, 3)``."""
    ident = identify(u, y, dt, "okid-eradc", ORDER)
    raw = mkr(ident.A, ident.B, ident.C, dt, SENSOR_DOFS, ACTUATOR_DOFS, "acceleration")
    alpha, beta = fit_proportional_damping(ident.modes.omega, ident.modes.damping_ratio)
    pendulum = pendulum_apparent_mass(rig)
    mass = raw.M.copy()
    mass[2, 2] -= pendulum
    structure = PhysicalModel(mass, raw.K, proportional_damping_matrix(mass, raw.K, alpha, beta))
    warnings = [*ident.warnings]
    if (pulse := unresolved_pulse(u)) is not None:
        warnings.append(pulse)
    return IdentifiedStructure(ident, raw, structure, alpha, beta, pendulum, tuple(warnings))


def save_structure(path: Path, result: IdentifiedStructure, inputs: list[str],
                   outputs: list[str], provenance: dict) -> None:
    """Write the model file the design reads (``design.model: file``), M, K, R the structure's."""

    provenance = {**provenance, "mkr": {"dofs": "0,1,2:0", "output": "acceleration"},
                  "rayleigh_alpha": result.rayleigh_alpha, "rayleigh_beta": result.rayleigh_beta,
                  "pendulum_apparent_mass": result.pendulum_mass,
                  "damping": "R = rayleigh_alpha M + rayleigh_beta K (eq. 3.242)"}
    save_model(path, model_from_identification(result.ident, inputs, outputs, provenance,
                                               result.structure))
