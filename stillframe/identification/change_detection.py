"""A change of the structure, decided from its tracked frequencies: a two-sided CUSUM per mode
(Page 1954, "Continuous inspection schemes", *Biometrika* 41; Basseville & Nikiforov 1993,
*Detection of Abrupt Changes*, §2.2, the two-sided CUSUM for a change in the mean).

Each update brings the frequencies of the modes identified in the latest window, ascending. The
first :attr:`CusumSettings.reference_updates` of them set the reference of each mode: μ_i their
mean and σ_i their standard deviation, at least :attr:`CusumSettings.min_relative_std` μ_i (a
handful of overlapping windows can agree more closely than the identification's noise). Then each
update adds its standardised deviation z_i = (f_i − μ_i)/σ_i to the two statistics of its mode,

    g⁺_i ← max(0, g⁺_i + z_i − ν),   g⁻_i ← max(0, g⁻_i − z_i − ν),

and a change is declared once one of them exceeds h. ν (``drift``) is the deviation an update
may show without accumulating; h (``threshold``) trades the delay against false alarms. The
change's onset is estimated as the first update of the run of nonzero statistics that crossed h
(the maximum-likelihood change time of the CUSUM; Basseville & Nikiforov eq. 2.2.32): the window
ending there holds changed samples, so the samples after its end are all of the new structure.

An update whose mode count differs from the reference's (a mode not found in that window, or a
spurious one) cannot be matched: it is skipped and counted, and the statistics stay.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import InputError

Array = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class CusumSettings:
    """The detector's constants (module docstring)."""

    reference_updates: int = 10
    drift: float = 1.0
    threshold: float = 20.0
    min_relative_std: float = 2e-4

    def check(self) -> None:
        """Raise :class:`~stillframe.errors.InputError` unless ``reference_updates`` is at least 2,
        ``drift`` non-negative and ``threshold`` and ``min_relative_std`` positive."""
        if self.reference_updates < 2:
            raise InputError("reference_updates: at least 2 (a spread needs two updates)")
        if not (self.drift >= 0 and self.threshold > 0 and self.min_relative_std > 0):
            raise InputError("drift >= 0, threshold > 0 and min_relative_std > 0")


@dataclass(frozen=True)
class Detection:
    """A change: when it was decided (``t``, the deciding update's window end), its estimated
    onset, the mode whose statistic crossed, the reference and the deciding frequencies."""

    t: float
    onset_t: float
    mode: int
    statistic: float
    reference_hz: Array
    reference_std_hz: Array
    frequency_hz: Array


@dataclass
class ChangeDetector:
    """The CUSUM of the module docstring over successive updates."""

    settings: CusumSettings = field(default_factory=CusumSettings)
    reference: list[Array] = field(default_factory=list)
    mean: Array | None = None
    std: Array | None = None
    upper: Array | None = None
    lower: Array | None = None
    run_start: Array | None = None
    skipped: int = 0

    def __post_init__(self) -> None:
        self.settings.check()

    @property
    def watching(self) -> bool:
        """Whether the reference is set (updates now feed the statistics)."""
        return self.mean is not None

    def statistic(self) -> float | None:
        """The largest CUSUM statistic over the modes (None while the reference is being set)."""
        if self.upper is None or self.lower is None:
            return None
        return float(max(self.upper.max(), self.lower.max()))

    def restart(self) -> None:
        """A new reference from the next updates (after a change was handled)."""
        self.reference, self.mean, self.std = [], None, None
        self.upper = self.lower = self.run_start = None

    def update(self, t: float, frequency_hz: Array) -> Detection | None:
        """One update's frequencies (ascending): the detection, when this update decides one."""
        f = np.sort(np.asarray(frequency_hz, dtype=float))
        expected = self.reference[0].size if self.reference else f.size
        if f.size == 0 or f.size != expected or not np.all(np.isfinite(f)):
            self.skipped += 1
            return None
        if self.mean is None:
            self.reference.append(f)
            if len(self.reference) == self.settings.reference_updates:
                self._set_reference()
            return None
        assert self.std is not None and self.upper is not None and self.lower is not None
        assert self.run_start is not None
        z = (f - self.mean) / self.std
        nu = self.settings.drift
        was_zero = (self.upper == 0) & (self.lower == 0)
        self.run_start = np.where(was_zero, t, self.run_start)
        self.upper = np.maximum(0.0, self.upper + z - nu)
        self.lower = np.maximum(0.0, self.lower - z - nu)
        statistic = np.maximum(self.upper, self.lower)
        mode = int(np.argmax(statistic))
        if statistic[mode] <= self.settings.threshold:
            return None
        return Detection(t, float(self.run_start[mode]), mode, float(statistic[mode]),
                         self.mean.copy(), self.std.copy(), f)

    def _set_reference(self) -> None:
        stack = np.vstack(self.reference)
        self.mean = stack.mean(axis=0)
        self.std = np.maximum(stack.std(axis=0, ddof=1),
                              self.settings.min_relative_std * self.mean)
        self.upper = np.zeros_like(self.mean)
        self.lower = np.zeros_like(self.mean)
        self.run_start = np.zeros_like(self.mean)
