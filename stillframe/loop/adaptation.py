"""The loop that notices a change of its structure and re-tunes itself (docs/adaptation.md):
:class:`Adaptation`, one object that the one-process loop and estimator_node both run on the same
records, so that both hand over the same design at the same sample.

Per sample k (after the estimator's step) :meth:`Adaptation.observe` takes the load cell, the
torque applied over the period before and the four measurements. Then, by sample count (never by
wall time):

1. **Detection.** Every ``adaptation.update_period`` from ``controller.start`` (and from each
   hand-over) on, the last ``detection_window`` of records is identified
   (:func:`stillframe.identification.loop_structure.identify_loop_modes`) and its frequencies feed
   a CUSUM per mode (:mod:`stillframe.identification.change_detection`); the first
   ``reference_updates`` set the reference.
2. **Re-identification.** Once a change is declared, the ``identification_window`` after its
   estimated onset is identified and MKR rebuilds the storeys
   (:func:`stillframe.identification.loop_structure.identify_loop_structure`); the design model
   is they with the rig's pendulum (:func:`stillframe.design.identified.storeys_frame`).
3. **Design and its checks** (:func:`check_design`): the scene's estimator and LQG on that model,
   gains finite, the regulator's poles eig(Φ − Γ K) and the filter's error poles
   eig((I − L C) Φ) inside the unit circle (by the separation principle, the LQG loop's poles on
   the design model are their union). A design that fails is refused (recorded with its reason)
   and the running one stays; detection starts again.
4. **Hand-over.** A design that passes is returned as a :class:`Handover` due at sample
   k + ``handover_periods``: the caller applies it before that sample's estimator step
   (:meth:`Handover.apply`): the estimator continues on the new model from its estimate, and the
   controller takes the new law at the same sample. Detection starts again from there.

Identification and design run when their window is complete, inside :meth:`observe`: in the
one-process loop and in a lock-step estimator_node the loop waits for them, so the hand-over
sample and every number after it are the same in both.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from stillframe.config.events import first_sample_at
from stillframe.config.scene import Scene
from stillframe.contract.signals import TORQUE, Sample
from stillframe.design.identified import storeys, storeys_frame
from stillframe.errors import StillframeError
from stillframe.identification.change_detection import ChangeDetector, CusumSettings
from stillframe.identification.loop_structure import identify_loop_modes, identify_loop_structure
from stillframe.loop.designs import Handover, check_adaptation, check_design, design_frequencies

__all__ = ["Adaptation"]

#: what an identification or a design may raise on records that do not support one
REFUSED = (StillframeError, np.linalg.LinAlgError, ValueError)


class Adaptation:
    """The adaptation of one run (module docstring)."""

    def __init__(self, scene: Scene, samples: int) -> None:
        check_adaptation(scene)
        a = scene.adaptation
        self.scene = scene
        self.period = period = 1.0 / scene.sensors.rate_hz
        self.detection = max(1, round(a.detection_window / period))
        self.every = max(1, round(a.update_period / period))
        self.identification = max(1, round(a.identification_window / period))
        self.delay = a.handover_periods
        self.t = np.full(samples, np.nan)
        self.u = np.full((samples, 2), np.nan)
        self.y = np.full((samples, 4), np.nan)
        self.detector = ChangeDetector(CusumSettings(
            reference_updates=a.reference_updates, drift=a.drift, threshold=a.threshold,
            min_relative_std=a.min_relative_std))
        self.watch_from = first_sample_at(scene.controller.start, period)
        self.identify_from: int | None = None
        self.designs = 0
        self.updates: list[dict[str, Any]] = []
        self.events: list[dict[str, Any]] = []

    # -- per sample ------------------------------------------------------------------------
    def observe(self, k: int, sample: Sample, applied: np.ndarray) -> Handover | None:
        """Sample ``k`` with the actuation ``applied`` over the period before it: a hand-over
        when this sample completes a design (due at a later sample), else None."""
        if k >= self.t.size:
            return None
        self.t[k] = sample.t
        self.u[k] = sample.force, applied[TORQUE]
        self.y[k] = sample.measurements
        if self.identify_from is None:
            since = k + 1 - self.watch_from
            if since >= self.detection and (since - self.detection) % self.every == 0:
                self._detect(k)
            return None
        if k + 1 - self.identify_from >= self.identification:
            return self._identify(k)
        return None

    def _window(self, k: int, length: int) -> tuple[np.ndarray, np.ndarray]:
        return self.u[k + 1 - length: k + 1], self.y[k + 1 - length: k + 1]

    def _detect(self, k: int) -> None:
        t = float(self.t[k])
        try:
            modes = identify_loop_modes(*self._window(k, self.detection), self.period).modes
        except REFUSED as exc:
            self.updates.append({"t": t, "frequency_hz": [], "error": str(exc),
                                 "statistic": self.detector.statistic()})
            return
        frequencies = np.sort(modes.frequency_hz)
        found = self.detector.update(t, frequencies)
        self.updates.append({"t": t, "frequency_hz": frequencies.tolist(), "error": None,
                             "statistic": self.detector.statistic()})
        if found is None:
            return
        self.identify_from = round(found.onset_t / self.period) + 1
        self.events.append({
            "kind": "detection", "t": t, "onset_s": found.onset_t, "mode": found.mode,
            "statistic": found.statistic, "reference_hz": found.reference_hz.tolist(),
            "reference_std_hz": found.reference_std_hz.tolist(),
            "frequency_hz": found.frequency_hz.tolist()})
        if k + 1 - self.identify_from >= self.identification:   # detected late: identify now
            self.identify_from = k + 1 - self.identification

    def _identify(self, k: int) -> Handover | None:
        t = float(self.t[k])
        first = k + 1 - self.identification
        window = [float(self.t[first]), t]
        self._watch_again(k + 1)
        try:
            found = identify_loop_structure(*self._window(k, self.identification), self.period,
                                            self.scene.rig)
            source = f"adaptation: records {window[0]:.6g}-{window[1]:.6g} s"
            structure = storeys(found.structure.M, found.structure.K, found.structure.R, source)
            design = storeys_frame(structure, self.scene.rig)
            estimator, controller, check = check_design(self.scene, design)
        except REFUSED as exc:
            self.events.append({"kind": "refusal", "t": t, "window_s": window,
                                "reason": str(exc)})
            return None
        self.designs += 1
        due = k + self.delay
        modes = found.ident.modes
        order = np.argsort(modes.frequency_hz)
        record = {
            "kind": "design", "design": self.designs, "t": t, "window_s": window,
            "handover_sample": due, "handover_s": due * self.period,
            "identified_hz": modes.frequency_hz[order].tolist(),
            "identified_damping": modes.damping_ratio[order].tolist(),
            "design_hz": design_frequencies(design).tolist(),
            "mass": structure.mass.tolist(), "stiffness": structure.stiffness.tolist(),
            "rayleigh_alpha": found.rayleigh_alpha, "rayleigh_beta": found.rayleigh_beta,
            "warnings": list(found.ident.warnings), **check.record()}
        self.events.append(record)
        self._watch_again(due)
        return Handover(due, due * self.period, structure, design, estimator, controller,
                        record)

    def _watch_again(self, k: int) -> None:
        """Detection from sample ``k`` on, with a new reference."""
        self.identify_from = None
        self.watch_from = k
        self.detector.restart()

    # -- the result --------------------------------------------------------------------------
    def report(self) -> dict[str, Any]:
        """The updates (time, frequencies or the refusal) and the events (detections, designs
        with their checks, refusals), in order: the result's ``adaptation``."""
        return {"updates": self.updates, "events": self.events,
                "skipped_updates": self.detector.skipped}
