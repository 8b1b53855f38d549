"""The watchdogs on sample time (stillframe.loop.watchdog): controller_node's zero command after
exactly ``watchdog_periods`` periods without a fresh estimate, once per sample time, and its
recovery; sim_node's safe state after ``command_timeout_periods`` (docs/nodes.md, watchdog)."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.contract.codecs import SampleGrid
from stillframe.contract.signals import Estimate
from stillframe.control.factory import make_controller
from stillframe.design.coordinates import design_map
from stillframe.loop.watchdog import EstimateWatchdog, command_expired
from stillframe.loop.wiring import design_model
from tests.support.scenes import thesis_scene


@pytest.mark.parametrize(("scene_name", "periods"), [("thesis_lqg", 3), ("thesis_lqg", 1),
                                                     ("thesis_euk_pendulum", 2)])
def test_zero_command_after_exactly_n_periods_then_recovery(scene_name: str,
                                                            periods: int) -> None:
    scene = thesis_scene(scene_name, [f"controller.watchdog_periods={periods}"])
    design = design_model(scene)
    controller = make_controller(scene, design)       # the real supervisor decides staleness
    period = 1.0 / scene.sensors.rate_hz
    grid = SampleGrid(period)
    watchdog = EstimateWatchdog(controller, grid)
    physical = np.zeros(8)
    z = design_map(design) @ physical

    def at(k: int) -> int:
        return grid.ns(k * period)

    def estimate(k: int) -> None:
        t = grid.seconds(at(k))
        assert not controller.command(t, Estimate(t, z, physical), 0.0).watchdog

    assert watchdog.due(at(7), waiting=False) is None     # not armed before a first estimate
    for start in (10, 10 + periods + 2):                  # trips, recovers, trips again
        estimate(start)
        for k in range(start, start + periods):
            assert watchdog.due(at(k), waiting=False) is None, k
        trip = at(start + periods)
        assert watchdog.due(trip, waiting=True) is None   # an estimate is still being answered
        t = watchdog.due(trip, waiting=False)
        assert t == (start + periods) * period            # the exact sample time
        assert watchdog.due(trip, waiting=False) is None  # once per sample time
        command = controller.command(t, None, 0.0)
        assert command.watchdog and not command.vector.any()
        assert watchdog.due(at(start + periods + 1), waiting=False) == grid.seconds(
            at(start + periods + 1))
    assert watchdog.due(-1, waiting=False) is None        # no sample time yet


def test_command_expires_after_exactly_the_limit() -> None:
    period_ns, limit = 31_250_000, 3 * 31_250_000
    assert not command_expired(12 * period_ns, 10 * period_ns, limit)
    assert command_expired(13 * period_ns, 10 * period_ns, limit)
    assert not command_expired(2 * period_ns, -1, limit)  # none yet: counted from time 0
    assert command_expired(3 * period_ns, -1, limit)
