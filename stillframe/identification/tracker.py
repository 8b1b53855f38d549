"""Live modal tracking: a sliding window of samples, identified again every few seconds.

:class:`ModalTracker` keeps the last ``window_s`` of input and output samples (aligned by stamp
by its caller) and, on :meth:`~ModalTracker.update`, identifies the window: with inputs by the
default path of :func:`stillframe.identification.pipeline.identify` (refined, with 95 %
intervals), without inputs by SSI-COV (:mod:`stillframe.identification.ssi_cov`). A window that
cannot be identified gives no modes and the refusal's text, never an exception: the tracker runs
beside a live loop.

The ``identification/modes`` message (``std_msgs/msg/Float64MultiArray``, :func:`modes_array`):
``layout.dim[0]`` = ``("modes", k, 6 k)``, ``layout.dim[1]`` = ``("fields", 6, 6)``, ``data`` row
by row, one row per mode ascending in frequency with the fields :data:`FIELDS`:
``frequency_hz, damping_ratio, frequency_ci_low, frequency_ci_high, damping_ci_low,
damping_ci_high``. An empty ``data`` means no trustworthy modes in the current window.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import StillframeError
from stillframe.identification.pipeline import identify
from stillframe.identification.report import interval
from stillframe.identification.ssi_cov import identify_output_only

Array = NDArray[np.float64]

FIELDS: tuple[str, ...] = ("frequency_hz", "damping_ratio", "frequency_ci_low",
                           "frequency_ci_high", "damping_ci_low", "damping_ci_high")
"""Columns of one mode's row in ``identification/modes``."""
#: the most samples in a row :meth:`ModalTracker.add` fills in; a longer gap restarts the window
MAX_FILL = 8
#: the line the tracker node logs once it subscribes: ``launch --track`` starts the loop's nodes
#: after it, so the window before control is whole however long the tracker's imports take
TRACKER_READY = "Modal tracker ready"

#: the tracker's exit code when stopped a second time with windows still due: each of them is
#: written as an update whose ``error`` begins with :data:`GIVEN_UP` (none is lost in silence)
EXIT_GIVEN_UP = 1
GIVEN_UP = "given up at the stop"

MODES_TOPIC = "identification/modes"
"""The tracker's topic, in the loop's namespace (``/frame/identification/modes``)."""


def mode_record(row: Sequence[float]) -> dict[str, Any]:
    """One mode's row (:data:`FIELDS`) as ``{"frequency_hz", "damping_ratio", "frequency_ci",
    "damping_ci"}``; an interval is None where the row holds NaN (none given: the update's
    warnings say why)."""
    f, z, f_low, f_high, z_low, z_high = (float(v) for v in row)
    return {"frequency_hz": f, "damping_ratio": z,
            "frequency_ci": interval(np.array([f_low, f_high])),
            "damping_ci": interval(np.array([z_low, z_high]))}


def mode_records(data: Sequence[float]) -> list[dict[str, Any]]:
    """The modes of an ``identification/modes`` message's ``data`` (module docstring)."""
    return [mode_record(row) for row in np.asarray(data, dtype=float).reshape(-1, len(FIELDS))]


@dataclass(frozen=True)
class TrackedModes:
    """One update: its time, the modes with intervals, the warnings or the refusal."""

    t: float
    frequency_hz: Array
    damping_ratio: Array
    frequency_ci_hz: Array
    damping_ci: Array
    warnings: tuple[str, ...] = ()
    error: str | None = None

    def record(self) -> dict[str, Any]:
        """``{"t", "modes": [{"frequency_hz", "damping_ratio", "frequency_ci", "damping_ci"}]}``
        (the launch JSON's ``tracked_modes`` entries), plus ``warnings`` and ``error``."""
        return {"t": self.t, "modes": [mode_record(row) for row in self.rows()],
                "warnings": list(self.warnings),
                "error": self.error}

    def rows(self) -> Array:
        """``(modes, 6)`` in the order of :data:`FIELDS`."""
        return np.column_stack([self.frequency_hz, self.damping_ratio, self.frequency_ci_hz,
                                self.damping_ci]) if self.frequency_hz.size else np.empty((0, 6))


def no_modes(t: float, error: str) -> TrackedModes:
    """An update of the window ending at ``t`` that gives no modes, and why."""
    empty = np.empty(0)
    return TrackedModes(t, empty, empty, np.empty((0, 2)), np.empty((0, 2)), error=error)


def modes_array(tracked: TrackedModes) -> tuple[list[tuple[str, int, int]], list[float]]:
    """The ``Float64MultiArray`` layout dims ``(label, size, stride)`` and data (module
    docstring)."""
    rows = tracked.rows()
    k = rows.shape[0]
    return [("modes", k, 6 * k), ("fields", 6, 6)], rows.ravel().tolist()


@dataclass
class ModalTracker:
    """Sliding window of ``(t, u, y)`` samples at period ``dt``; identifies on :meth:`update`."""

    dt: float
    window_s: float
    order: int | str = "auto"
    _t: deque = field(default_factory=deque)
    _u: deque = field(default_factory=deque)
    _y: deque = field(default_factory=deque)
    #: samples filled in for ones missing, and windows started afresh after a longer gap
    filled: int = 0
    restarts: int = 0

    @property
    def capacity(self) -> int:
        return max(1, round(self.window_s / self.dt))

    def add(self, t: float, u: Array, y: Array) -> None:
        """One aligned sample (``u`` may be empty: output-only). Samples missing before it (a
        subscriber that lost some under load) are filled in linearly and counted (``filled``),
        up to :data:`MAX_FILL` in a row; a longer gap starts the window afresh (``restarts``):
        the identification assumes one sample every ``dt``, and a window with samples left out
        would read every frequency too high."""
        u, y = np.asarray(u, dtype=float), np.asarray(y, dtype=float)
        missing = round((t - self._t[-1]) / self.dt) - 1 if self._t else 0
        if missing > MAX_FILL:
            self.restarts += 1
            for store in (self._t, self._u, self._y):
                store.clear()
        elif missing > 0:
            t0, u0, y0 = self._t[-1], self._u[-1], self._y[-1]
            for k in range(1, missing + 1):
                w = k / (missing + 1)
                self._append(t0 + w * (t - t0), u0 + w * (u - u0), y0 + w * (y - y0))
            self.filled += missing
        self._append(t, u, y)

    def _append(self, t: float, u: Array, y: Array) -> None:
        for store, value in ((self._t, t), (self._u, u), (self._y, y)):
            store.append(value)
            if len(store) > self.capacity:
                store.popleft()

    @property
    def samples(self) -> int:
        return len(self._t)

    def window(self) -> Window:
        """A copy of the current window (identify it with :func:`identify_window`, on another
        thread if need be, while samples keep coming)."""
        return Window(float(self._t[-1]) if self._t else 0.0, np.array(self._u),
                      np.array(self._y), self.dt, self.order)

    def update(self) -> TrackedModes:
        """Identify the current window; a refusal is returned as ``error``, not raised."""
        return identify_window(self.window())


@dataclass(frozen=True)
class Window:
    """The samples of one window: last sample time, inputs, outputs, period, order."""

    t: float
    u: Array
    y: Array
    dt: float
    order: int | str


def identify_window(window: Window) -> TrackedModes:
    """The window's modes (module docstring); a refusal is returned as ``error``, not raised."""
    t, u, y = window.t, window.u, window.y
    try:
        if u.size:
            ident = identify(u.reshape(len(u), -1), y, window.dt, order=window.order)
            ref = ident.refinement
            if ref is None:
                raise StillframeError("the window's model is not refined: no intervals")
            return TrackedModes(t, ident.modes.frequency_hz, ident.modes.damping_ratio,
                                ref.frequency_ci_hz, ref.damping_ci, ident.warnings)
        out = identify_output_only(y, window.dt, window.order)
        return TrackedModes(t, out.modes.frequency_hz, out.modes.damping_ratio,
                            out.frequency_ci_hz, out.damping_ci, out.warnings)
    except (StillframeError, np.linalg.LinAlgError, ValueError) as exc:
        return no_modes(t, str(exc))
