"""Durations [s] kept in a preallocated ring: a loop's per-sample timings without growth.

Used by the loop nodes (latencies, compute times) and the controller (its law's time per
sample), so that a long run at 1 kHz neither grows a list nor reallocates one in the loop.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Durations"]

#: the quantiles a report gives besides the max (p50, p99)
QUANTILES = (0.5, 0.99)


class Durations:
    """Wall-clock durations [s] (latencies, compute times) kept in a preallocated ring of the
    last ``keep``: percentiles in ms over all of them (:meth:`summary`, for a run's result) or
    over those added since the last report (:meth:`recent`, for ``/diagnostics``). A report
    costs what its window holds, not the whole run (percentiles over 10⁵ values take
    milliseconds, too long for the loop)."""

    def __init__(self, keep: int = 100_000) -> None:
        self.values = np.empty(keep)
        self.count = 0              # values added, ever
        self.reported = 0           # ``count`` at the last :meth:`recent`

    def add(self, seconds: float) -> None:
        """Add one duration [s], overwriting the oldest once the ring is full."""
        self.values[self.count % len(self.values)] = seconds
        self.count += 1

    def summary(self) -> dict[str, float]:
        """Over every value kept."""
        return self._percentiles(self.values[:min(self.count, len(self.values))])

    def recent(self) -> dict[str, float]:
        """Over the values added since the last call (at most ``keep``)."""
        n = min(self.count - self.reported, len(self.values))
        self.reported = self.count
        end = self.count % len(self.values)
        window = (self.values[end - n:end] if n <= end
                  else np.concatenate([self.values[end - n:], self.values[:end]]))
        return self._percentiles(window)

    @staticmethod
    def _percentiles(seconds: np.ndarray) -> dict[str, float]:
        """p50, p99 and max in ms: numpy's default (linear) percentiles, from one partial sort
        (``np.percentile`` goes through several Python layers for the same result, which a
        node's status pays inside the loop)."""
        n = len(seconds)
        if not n:
            return {"p50": float("nan"), "p99": float("nan"), "max": float("nan")}
        ranks = (n - 1) * np.asarray(QUANTILES)
        below = ranks.astype(int)
        above = np.minimum(below + 1, n - 1)
        ordered = np.partition(seconds, np.unique(np.concatenate([below, above, [n - 1]])))
        p50, p99 = ordered[below] + (ordered[above] - ordered[below]) * (ranks - below)
        return {"p50": 1e3 * float(p50), "p99": 1e3 * float(p99),
                "max": 1e3 * float(ordered[n - 1])}
