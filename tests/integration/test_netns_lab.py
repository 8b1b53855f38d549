"""The three-host lab in network namespaces and its faults, measured with plain UDP: addresses
and reachability over the bridge, removal (also after a failure half-way), the loss rate of the
loss faults (binomial bounds) and the delay queue's delays and reordering."""

from __future__ import annotations

import itertools
import os
import subprocess

import numpy as np
import pytest

from stillframe.app import netns_lab
from stillframe.app.net_faults import Fault, applied
from stillframe.errors import InputError
from tests.support.netns import require_netns, udp_probe


@pytest.fixture
def prefix() -> str:
    require_netns()
    name = f"sft{os.getpid() % 100000}"
    yield name
    netns_lab.down(name)


def ours(prefix: str) -> list[str]:
    return [n for n in netns_lab.namespaces() if n.startswith(f"{prefix}-")]


def root_link_exists(name: str) -> bool:
    return subprocess.run(["ip", "link", "show", name], capture_output=True).returncode == 0


def test_lab_joins_three_hosts_and_is_removed(prefix: str) -> None:
    with netns_lab.lab(prefix) as lab:
        assert sorted(ours(prefix)) == sorted(f"{prefix}-{h}" for h in ("sim", "est", "ctl", "br"))
        assert root_link_exists(lab.observer_interface)
        # sim -> est and est -> the root namespace's interface, both over the bridge
        assert len(udp_probe(lab.namespace("sim"), lab.namespace("est"), str(lab.address("est")),
                             20)) == 20
        routes = subprocess.run(["ip", "-n", lab.namespace("ctl"), "route"], capture_output=True,
                                text=True).stdout
        assert "224.0.0.0/4 dev eth0" in routes
        with pytest.raises(InputError, match="exists"):
            netns_lab.up(prefix)
    assert ours(prefix) == []
    assert not root_link_exists(f"{prefix}h")


def test_a_failure_half_way_leaves_nothing(prefix: str, monkeypatch: pytest.MonkeyPatch) -> None:
    real, calls = netns_lab._ip, []

    def failing(*args: str) -> None:
        calls.append(args)
        if len(calls) == 12:
            raise InputError("made to fail")
        real(*args)

    monkeypatch.setattr(netns_lab, "_ip", failing)
    with pytest.raises(InputError, match="made to fail"):
        netns_lab.up(prefix)
    assert ours(prefix) == []


@pytest.mark.parametrize("bad", ["", "1abc", "UPPER", "abcdefghijk", "a-b"])
def test_prefix_is_checked(bad: str) -> None:
    with pytest.raises(InputError, match="--prefix"):
        netns_lab.check_prefix(bad)


def test_loss_rate_and_rules_removed(prefix: str) -> None:
    require_netns("iptables")
    n, p = 2000, 0.30
    with netns_lab.lab(prefix) as lab:
        with applied(lab, Fault("loss", loss=p)):
            got = len(udp_probe(lab.namespace("sim"), lab.namespace("est"),
                                str(lab.address("est")), n))
        after = len(udp_probe(lab.namespace("sim"), lab.namespace("est"),
                              str(lab.address("est")), 200))
    # received ~ Binomial(n, 1 - p): within 5 standard deviations
    assert abs(got - n * (1 - p)) < 5 * np.sqrt(n * p * (1 - p)), got
    assert after == 200


def test_delay_queue_delays_by_at_least_the_low_end_and_reorders(prefix: str) -> None:
    require_netns("iptables")
    with netns_lab.lab(prefix) as lab, applied(lab, Fault("delay", delay_ms=5, jitter_ms=2)):
        received = udp_probe(lab.namespace("sim"), lab.namespace("est"), str(lab.address("est")),
                             500)
    indices = [i for i, _ in received]
    delays = np.array([d for _, d in received])
    assert sorted(indices) == list(range(500))        # nothing lost
    assert delays.min() >= 3e-3                         # 5 ms − 2 ms: never earlier
    # sent back to back in bursts, delays spread over 4 ms: some overtake others
    assert sum(b < a for a, b in itertools.pairwise(indices)) > 0
