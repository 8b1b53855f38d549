"""A fixed actuation delay of d sample periods (scene ``actuators.delay_periods``).

The command stamped t_k is applied over [t_k+d, t_k+d+1). Commands wait here by their sample
index until their period starts: a playout buffer, as networked control puts at the actuator to
turn a network's varying delay into a constant one that the controller can predict over
(``stillframe.control.prediction``). A command that has not arrived when its period starts is
late: the actuators hold the last one applied (zero before the first), and it counts as a
deadline miss. With d = 0 a command is applied in the period of the sample it answers, and the
simulator waits for it (the thesis's set-up).
"""

from __future__ import annotations

import numpy as np


class ActuationDelay:
    """Commands [torque, force] by the sample index they answer, applied ``periods`` later."""

    def __init__(self, periods: int) -> None:
        self.periods = periods
        self._waiting: dict[int, np.ndarray] = {}
        self.held = np.zeros(2)

    def put(self, k: int, command: np.ndarray) -> None:
        """The command answering sample ``k`` (a later one for the same k replaces it). Those
        answering samples before k − d are dropped: their periods began before sample k was
        taken, so they can never be due (and with d = 0 a caller that applies the newest
        command itself, as sim_node does, never calls :meth:`due`)."""
        self._waiting[k] = np.array(command, dtype=float)
        for old in [j for j in self._waiting if j < k - self.periods]:
            del self._waiting[old]

    def __len__(self) -> int:
        """Commands waiting for their period."""
        return len(self._waiting)

    def due(self, k: int) -> tuple[np.ndarray, bool]:
        """The command to apply over period k: the one answering sample k − d, or the one held
        when it is not here (True: it was late; never before period d)."""
        answered = k - self.periods
        command = self._waiting.pop(answered, None)
        for old in [j for j in self._waiting if j < answered]:
            del self._waiting[old]    # came after its period began: too late to apply
        if command is not None:
            self.held = command
        return self.held.copy(), command is None and answered >= 0
