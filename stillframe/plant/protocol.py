"""What the loop asks of a simulated rig: the :class:`Plant` protocol.

:class:`~stillframe.plant.frame_plant.FramePlant` (the lumped, finite-element, Craig–Bampton and
identified models on the integrators) and :class:`~stillframe.plant.ph_plant.PHPlant` (the frame
pHDAE on its AVF midpoint rule) implement it; :func:`~stillframe.plant.frame_plant.make_plant`
picks one from the scene. The one-process loop, sim_node and the benchmarks call only these.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from stillframe.contract.signals import Sample
from stillframe.plant.actuators import Actuators

__all__ = ["Plant"]


class Plant(Protocol):
    """A rig stepped one sample period at a time: :meth:`sample` at t_k (the actuation of the
    period before still applied), then :meth:`advance` with the command of the period."""

    period: float
    """The sample period [s]."""
    substeps: int
    """Integrator steps per period."""
    h: float
    """The integrator step [s]."""
    k: int
    """Periods advanced so far."""
    model: Any
    """The model simulated (its ``name`` goes into the result)."""
    integrator: Any
    """The integrator (its ``name`` goes into the result)."""
    actuators: Actuators

    @property
    def subdivisions(self) -> int:
        """Integrator steps halved so far (:mod:`stillframe.dynamics.integrators`)."""

    def warm_up(self) -> None:
        """Load or compile the kernels now, outside the loop; the state does not change."""

    def sample(self) -> Sample:
        """The sensor readings and the true state at t_k = k · period."""

    def advance(self, command: np.ndarray) -> np.ndarray:
        """Apply [torque, floor-3 force] through the actuators over one period; returns what
        they applied (after saturation and slew limits)."""

    def change_structure(self, index: int) -> None:
        """From now on the structure after the scene's event ``index``
        (:mod:`stillframe.config.events`), the state carried over; called by the loop's step
        at the event's sample boundary, before :meth:`sample`."""

    def truth_history(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Times, floor displacements (N×3) and velocities (N×3) at every integrator step."""
