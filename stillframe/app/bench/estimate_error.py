"""The estimate's error against the simulator's truth, seen by an outside observer.

The observer collects ``state_estimate`` by stamp; the simulator's truth history (what it
published on ``state_truth``, row k at t_k = k·period) gives the reference. The RMS error is
taken over the samples both have, per channel of [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇].
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stillframe.contract.codecs import physical_state


@dataclass
class EstimateLog:
    """Estimates by sample index k = stamp / period (the first one for a stamp counts)."""

    period_ns: int
    estimates: dict[int, np.ndarray] = field(default_factory=dict)

    def on_estimate(self, msg: Any) -> None:
        """Keep the first estimate of each sample, indexed by its stamp on the period's grid."""
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.estimates.setdefault(round(stamp / self.period_ns), physical_state(msg))

    def rms_error(self, truth: np.ndarray, from_k: int = 0) -> dict[str, Any]:
        """RMS of estimate − truth over the finite samples k ≥ ``from_k`` both have: per
        channel (``rms``), over the three floors' displacements (``rms_floors_m``) and of φ
        (``rms_phi_rad``); the floors' error relative to their RMS displacement over the same
        samples (``relative_floors``); ``samples`` used, ``missing`` (no estimate for a truth
        row)."""
        ks = [k for k in range(from_k, len(truth)) if k in self.estimates]
        estimates = np.array([self.estimates[k] for k in ks]).reshape(-1, 8)
        reference = truth[ks].reshape(-1, 8)
        finite = np.all(np.isfinite(estimates - reference), axis=1)
        error, reference = (estimates - reference)[finite], reference[finite]
        if not len(error):
            nan = float("nan")
            return {"samples": 0, "missing": len(truth) - from_k - len(ks),
                    "rms": [nan] * 8, "rms_floors_m": nan, "rms_phi_rad": nan,
                    "relative_floors": nan}
        rms = np.sqrt(np.mean(error ** 2, axis=0))
        floors = float(np.sqrt(np.mean(error[:, :3] ** 2)))
        return {"samples": len(error), "missing": len(truth) - from_k - len(ks),
                "rms": rms.tolist(), "rms_floors_m": floors, "rms_phi_rad": float(rms[3]),
                "relative_floors": floors / float(np.sqrt(np.mean(reference[:, :3] ** 2)))}
