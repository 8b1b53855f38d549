"""A late input re-runs the filter (stillframe.loop.refilter, docs/nodes.md real-time mode): a
reading that comes after its stamp was used without it (the encoder, with the torque applied; for
the EUK scene's floor-3 force, its load cell) leaves the filter in the state of one whose inputs
all came in time, to the last bit, for each filter type. The reference is the filter
stepped directly with every sample complete; without the re-run (or past its window) the state
differs from it."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.config.scene import Scene
from stillframe.contract.codecs import ENCODER_CHANNEL, SENSOR_TOPICS, SampleGrid
from stillframe.contract.signals import Sample, actuator_of
from stillframe.estimation.base import Filter
from stillframe.estimation.factory import make_estimator
from stillframe.loop.assembly import SampleAssembly
from stillframe.loop.refilter import StepHistory
from stillframe.loop.wiring import design_model, estimator_inputs
from tests.support.scenes import thesis_scene

PERIOD = 1 / 32                 # the thesis scene's sample rate
PERIOD_NS = 31_250_000
WAIT_NS = PERIOD_NS // 2        # half a period, the default partial_after_s
STAMPS = 24
LATE_K = 10                     # the stamp whose input comes late
rng = np.random.default_rng(7)
READINGS = rng.normal(scale=[0.05, 0.05, 0.05, 0.01, 2.0], size=(STAMPS, 5))
APPLIED = rng.normal(scale=0.2, size=STAMPS)    # the active actuator's, as reported


def _scene(kind: str) -> Scene:
    """The LQG scene with a linear filter; the EUK scene with its EKF."""
    if kind == "ekf":
        return thesis_scene("thesis_euk_ekf")
    return thesis_scene("thesis_lqg", [f"estimator.type={kind}"])


def _reference(kind: str) -> Filter:
    """Every sample complete, stepped in order."""
    scene = _scene(kind)
    est = make_estimator(scene, design_model(scene))
    control = np.zeros(2)
    for k in range(STAMPS):
        control[actuator_of(scene)] = APPLIED[k]
        est.step(Sample(k * PERIOD, READINGS[k, :4].copy(), float(READINGS[k, 4])),
                 control.copy())
    return est


def _realtime(kind: str, revisable: int, late_by: int) -> tuple[Filter, SampleAssembly]:
    """The samples through an assembly in real time, stamp LATE_K's encoder reading (or, with the
    floor-3 force commanded, its load cell) arriving ``late_by`` periods after its other inputs
    (its stamp used partial, at its timeout, before it)."""
    scene = _scene(kind)
    est = make_estimator(scene, design_model(scene))
    active = actuator_of(scene)
    a = SampleAssembly(estimator_inputs(scene), active, SampleGrid(PERIOD), WAIT_NS, False,
                       revisable=revisable)
    history = StepHistory(revisable)

    def inputs(k: int, now: int, *, late: bool) -> None:
        torque = APPLIED[k] if active == 0 else 0.0
        if late == (active == 0):
            a.reading(ENCODER_CHANNEL, k * PERIOD_NS, READINGS[k, ENCODER_CHANNEL], now, torque)
        if late == (active == 1):
            a.applied_force(k * PERIOD_NS, APPLIED[k], now)
        if not late:
            for c in {*range(5)} - {ENCODER_CHANNEL}:
                a.reading(c, k * PERIOD_NS, READINGS[k, c], now)

    for k in range(STAMPS):
        now = k * PERIOD_NS
        inputs(k, now, late=False)
        if k != LATE_K:
            inputs(k, now, late=True)
        if k == LATE_K + late_by:
            inputs(LATE_K, now, late=True)
        if revised := a.take_revision():
            assert [r.ns for r in revised] == [LATE_K * PERIOD_NS] and revised[0].complete
            assert revised[0].control[active] == APPLIED[LATE_K]    # the report, not a guess
            assert history.refilter(est, revised)
        while (ready := a.pop_ready(now + WAIT_NS)) is not None:    # past every timeout
            history.step(est, ready)
            a.used(ready.ns)
    return est, a


@pytest.mark.parametrize("kind", ["kf", "tvkf", "ekf"])
@pytest.mark.parametrize("late_by", [1, 6])     # 6: the last stamp 5 periods on, the edge
def test_a_late_reading_leaves_the_filter_as_if_it_came_in_time(kind: str, late_by: int) -> None:
    reference = _reference(kind)
    est, a = _realtime(kind, revisable=5, late_by=late_by)
    assert a.counts["partial_updates"] == 1 and a.counts["late_inputs"] == 1
    assert a.counts["stale_messages"] == 0
    np.testing.assert_array_equal(est.x, reference.x)
    np.testing.assert_array_equal(est.P, reference.P)
    assert est.t == reference.t and est.force == reference.force
    assert est.counters == reference.counters          # no channel missing, each stamp once


@pytest.mark.parametrize(("revisable", "late_by"), [(0, 2), (5, 7)])
def test_without_a_rerun_or_past_its_window_the_reading_is_stale(revisable: int,
                                                                  late_by: int) -> None:
    reference = _reference("kf")
    est, a = _realtime("kf", revisable=revisable, late_by=late_by)
    assert a.counts["late_inputs"] == 0 and a.counts["stale_messages"] == 1
    assert est.counters.missing == 1                  # the encoder's channel
    assert np.abs(est.x - reference.x).max() > 1e-9


def test_a_repeated_late_reading_is_stale_and_revises_nothing() -> None:
    a = SampleAssembly(SENSOR_TOPICS, 0, SampleGrid(PERIOD), WAIT_NS, False, revisable=3)
    for c in range(4):
        a.reading(c, 0, 0.1, 0, 0.0)
    ready = a.pop_ready(WAIT_NS)
    assert ready is not None and not ready.complete
    a.used(ready.ns)
    a.reading(4, 0, 0.2, WAIT_NS + 1)
    assert [r.sample.force for r in a.take_revision()] == [0.2]
    a.reading(4, 0, 0.2, WAIT_NS + 2)
    assert a.take_revision() == []
    assert a.counts["late_inputs"] == 1 and a.counts["stale_messages"] == 1
