"""When a node publishes its ``/diagnostics`` status (stillframe.node_runtime.support.Diagnostics)
on a fake clock, with a real node and a reader of what it wrote: once a period, in real time only
in a turn whose time before the next sample holds what the last status took, never more than one
more period late, and the waits counted in the status itself."""

from __future__ import annotations

import pytest

from stillframe.contract import topics
from stillframe.middleware import api
from stillframe.node_runtime import support
from stillframe.node_runtime.support import Diagnostics, diagnostic_values
from tests.support.waits import HANG_S


class FakeClock:
    """``time.monotonic`` and ``time.monotonic_ns`` on one settable clock."""

    def __init__(self) -> None:
        self.ns = 0

    def monotonic(self) -> float:
        return self.ns * 1e-9

    def monotonic_ns(self) -> int:
        return self.ns


@pytest.mark.processes
def test_a_status_waits_for_slack_that_holds_its_cost_at_most_one_period(
        ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    clock = FakeClock()
    monkeypatch.setattr(support, "time", clock)
    node = api.create_node("sim_node", namespace="/frame", argv=["x"], backend="dds")
    reader = api.create_node("reader", namespace="/frame", argv=["x"], backend="dds")
    statuses: list = []
    reader.create_subscription(topics.DIAGNOSTICS.type_name, topics.DIAGNOSTICS.name,
                               statuses.append, topics.DIAGNOSTICS.qos)
    try:
        d = Diagnostics(node, period_s=1.0)
        assert api.spin_until(reader, lambda: d.pub.get_subscription_count() > 0, HANG_S)
        clock.ns = 999_999_999
        assert not d.due(None)                          # not a period yet
        clock.ns = 1_000_000_000
        assert d.due(0)                                 # no cost known yet: at once
        clock.ns += 300_000                             # the status takes 300 µs
        d.publish(1, {"step": 1})
        assert d.cost_ns == 300_000
        clock.ns = 2_100_000_000
        assert not d.due(299_999)                       # the next sample is too close
        assert d.due(None)                              # no deadline (lock-step): now
        clock.ns += 100_000
        d.publish(2, {"step": 2})
        assert d.cost_ns == 100_000
        clock.ns = 3_200_000_000
        assert not d.due(99_999) and d.due(100_000)     # the last status's cost, exactly
        clock.ns += 200_000
        d.publish(3, {"step": 3})                       # next due at 4.2002 s
        clock.ns = 4_300_000_000
        assert not d.due(199_999)
        clock.ns = 5_200_199_999
        assert not d.due(0)
        clock.ns = 5_200_200_000                        # a whole period late: whatever the slack
        assert d.due(0)
        d.publish(4, {"step": 4})
        assert d.deferred == 3                          # statuses 2, 3 and 4 waited
        assert api.spin_until(reader, lambda: len(statuses) == 4, HANG_S)
    finally:
        reader.destroy_node()
        node.destroy_node()
    assert [diagnostic_values(m)["statuses_deferred"] for m in statuses] == ["0", "1", "2", "3"]
    assert [diagnostic_values(m)["step"] for m in statuses] == ["1", "2", "3", "4"]
