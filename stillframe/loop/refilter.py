"""Stepping a filter again from a stamp that a late input revised (real time).

A stamp used with some of its inputs missing is a partial update. When a missing input comes
later, within the assembly's ``revisable`` stamps (:meth:`SampleAssembly.take_revision
<stillframe.loop.assembly.SampleAssembly.take_revision>`), the filter goes back to its state before
that stamp and steps every stamp since again, the revised ones as they now stand. Its state is
then the one it would have had if the input had come in time: the same operations on the same
numbers. The estimates already published are not sent again; the next ones carry the input.
"""

from __future__ import annotations

from collections import deque

from stillframe.contract.signals import Estimate
from stillframe.estimation.base import Filter, FilterState
from stillframe.estimation.factory import Estimator
from stillframe.loop.assembly import Ready

__all__ = ["StepHistory"]


class StepHistory:
    """The last ``depth`` + 1 stamps an estimator stepped, each with the filter's state before it
    (none kept for ``depth`` 0, or for an estimator that is not a filter)."""

    def __init__(self, depth: int) -> None:
        self.entries: deque[tuple[FilterState, Ready]] = deque(maxlen=depth + 1 if depth else 0)

    def clear(self) -> None:
        """Forget every stamp: no stepping back past a filter's start or a new design."""
        self.entries.clear()

    def step(self, estimator: Estimator, ready: Ready) -> Estimate | None:
        """``estimator.step`` with the stamp ``ready``, its state before kept."""
        if self.entries.maxlen and isinstance(estimator, Filter):
            self.entries.append((estimator.state(), ready))
        return estimator.step(ready.sample, ready.control)

    def refilter(self, estimator: Estimator, revised: list[Ready]) -> bool:
        """Step ``estimator`` again from the oldest of the ``revised`` stamps still kept, each
        stamp since as it now stands; whether it did (False: none of them is kept)."""
        by_ns = {r.ns: r for r in revised}
        start = next((i for i, (_, r) in enumerate(self.entries) if r.ns in by_ns), None)
        if start is None or not isinstance(estimator, Filter):
            return False
        estimator.restore(self.entries[start][0])
        for i in range(start, len(self.entries)):
            ready = by_ns.get(self.entries[i][1].ns, self.entries[i][1])
            self.entries[i] = (estimator.state(), ready)
            estimator.step(ready.sample, ready.control)
        return True
