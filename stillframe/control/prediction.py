"""State prediction over a fixed actuation delay (scene ``actuators.delay_periods``).

With the command stamped t_k applied from t_k+d on (``stillframe.plant.actuation_delay``), the
design model runs x_{j+1} = A x_j + B u_{j−d}. At sample k the commands u_{k−d} … u_{k−1} are
already sent but not yet applied, so the state the new command will act on is

    x̂_{k+d|k} = A^d x̂_k + Σ_{j=k−d}^{k−1} A^{k−1−j} B u_j,

and u_k = −K x̂_{k+d|k} gives the delay-free loop's poles back on the design model (the
predictor form of state feedback for input delay; Åström & Wittenmark, *Computer-Controlled
Systems*, §7.6, "sampled-data systems with time delay"). A command that was not sent for some
sample (no estimate came) is taken as held, as the actuators hold it.

The sum holds only while the actuator applies the commands. In the simulator's safe state (its
command timeout, or the guard of a degraded control path) it applies zero, the commands sent stop
reaching the state, and u_k = −K (A^d x̂_k + Σ A^{k−1−j} B u_j) becomes a recursion in u alone:
its roots are those of z^d + Σ_{i=1}^{d} K A^{i−1} B z^{d−i}, outside the unit circle for the
thesis LQG at 100 Hz (1.15 for d = 3), so the commands grow each period and the first one
applied again throws the structure. This is the predictor's windup; as for the estimator
(observer-based anti-windup), the cure is the actuation applied. The estimate carries what the
simulator reported it applied over the period before it: zero where the command sent for that
period was not zero is the safe state, and the commands in flight are then taken as zero. Any
other difference is a command held for one late one, or a saturation: the commands in flight
still reach the actuator then, and the prediction stays the sum over them.
"""

from __future__ import annotations

import bisect

import numpy as np

#: periods of commands kept before the newest one's prediction window: an estimate this late
#: (behind a command the controller's watchdog sent for a later sample) still predicts over the
#: commands that were sent, not over forgotten ones read as 0
KEPT_PERIODS = 64


class CommandLog:
    """Commands by the sample index they answer. The one in effect at sample j is the newest
    at or before j (the actuators hold the last command; 0 before any). The indices are kept
    sorted, so a lookup is a bisection, however many the log keeps."""

    def __init__(self) -> None:
        self._by_index: dict[int, float] = {}
        self._indices: list[int] = []

    def record(self, k: int, value: float) -> None:
        """Remember ``value`` as the command issued at sample ``k``."""
        if k not in self._by_index:
            bisect.insort(self._indices, k)
        self._by_index[k] = value

    def in_effect(self, j: int) -> float:
        """The command in effect at sample ``j``: the newest recorded at or before it (0 before
        any)."""
        i = bisect.bisect_right(self._indices, j)
        return self._by_index[self._indices[i - 1]] if i else 0.0

    def forget_before(self, k: int) -> None:
        """Drop what no sample from k on needs: the commands before k but the newest of them."""
        drop = bisect.bisect_left(self._indices, k) - 1
        if drop > 0:
            for j in self._indices[:drop]:
                del self._by_index[j]
            del self._indices[:drop]


class DelayPredictor:
    """x̂_{k+d|k} on the discrete design model (A, B) of period ``period`` for d = ``periods``,
    from the commands sent (:meth:`sent`)."""

    def __init__(self, A: np.ndarray, B: np.ndarray, periods: int, period: float) -> None:
        self.A = A
        self.B = B.reshape(-1)
        self.periods = periods
        self.period = period
        self._sent = CommandLog()

    def index(self, t: float) -> int:
        """The sample index of time ``t`` [s] on the period's grid."""
        return round(t / self.period)

    def sent(self, t: float, value: float) -> None:
        """The command sent for the sample at ``t`` (the next prediction starts at sample
        k + 1 − d)."""
        k = self.index(t)
        self._sent.record(k, value)
        # an estimate may come after a later sample's command (the watchdog's zero): the
        # commands it predicts over are kept for KEPT_PERIODS
        self._sent.forget_before(k + 1 - self.periods - KEPT_PERIODS)

    def ahead(self, t: float, z: np.ndarray, applied: float | None = None) -> np.ndarray:
        """x̂_{k+d|k} from the estimate ``z`` of the sample at ``t``; ``applied``: the actuation
        over the period before it, as the estimate took it (None or NaN: not known). Zero where
        the command sent for that period was not is the simulator's safe state: the commands in
        flight are then taken as zero (module docstring)."""
        k = self.index(t)
        safe_state = applied == 0.0 and self._sent.in_effect(k - 1 - self.periods) != 0.0
        for j in range(k - self.periods, k):
            z = self.A @ z + self.B * (0.0 if safe_state else self._sent.in_effect(j))
        return z
