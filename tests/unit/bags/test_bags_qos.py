"""QoS between the middleware and bags, against rosbag2's rules (``rosbag2_storage/qos.cpp``:
``adapt_request_to_offers``, ``adapt_offer_to_recorded_offers``) and its v9 metadata form."""

from __future__ import annotations

import pytest
from rosbags.interfaces import QosReliability
from rosbags.interfaces import QosTime as BagTime
from rosbags.rosbag2.metadata import dump_qos_v9

from stillframe.bags.qos import from_bag, player_offer, to_bag
from stillframe.middleware.qos import (
    CLOCK,
    DEFAULT,
    PROFILES,
    RECORD_DEPTH,
    SENSOR_DATA,
    Durability,
    History,
    QoSProfile,
    Reliability,
    recorder_request,
)

LATCHED = QoSProfile(depth=1, durability=Durability.TRANSIENT_LOCAL)
INFINITE = {"sec": 9223372036, "nsec": 854775807}


def test_sensor_data_in_metadata_as_rosbag2_v9_writes_it() -> None:
    assert dump_qos_v9([to_bag(SENSOR_DATA)]) == [{
        "history": "keep_last", "depth": 5, "reliability": "best_effort",
        "durability": "volatile", "deadline": INFINITE, "lifespan": INFINITE,
        "liveliness": "automatic", "liveliness_lease_duration": INFINITE,
        "avoid_ros_namespace_conventions": False}]


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_profiles_survive_the_bag(name: str) -> None:
    assert from_bag(to_bag(PROFILES[name])) == PROFILES[name]


def test_finite_durations_survive_the_bag() -> None:
    profile = QoSProfile(deadline_ns=1_500_000_000, lifespan_ns=7)
    bag = to_bag(profile)
    assert (bag.deadline.sec, bag.deadline.nsec, bag.lifespan.nsec) == (1, 500_000_000, 7)
    assert from_bag(bag) == profile


@pytest.mark.parametrize("sec_nsec", [(2147483647, 4294967295), (2147483647, 2147483647)])
def test_foxy_era_infinities_read_as_infinite(sec_nsec: tuple[int, int]) -> None:
    """Fast DDS's and Connext's old "infinite" (rosbag2_storage/qos.cpp translates them)."""
    old = to_bag(DEFAULT)._replace(deadline=BagTime(*sec_nsec), lifespan=BagTime(*sec_nsec))
    assert from_bag(old) == DEFAULT


def test_unknown_policies_fall_back_to_the_default() -> None:
    odd = to_bag(SENSOR_DATA)._replace(reliability=QosReliability.BEST_AVAILABLE)
    assert from_bag(odd).reliability == DEFAULT.reliability


@pytest.mark.parametrize(("offers", "reliability", "durability"), [
    ([DEFAULT], Reliability.RELIABLE, Durability.VOLATILE),
    ([SENSOR_DATA], Reliability.BEST_EFFORT, Durability.VOLATILE),
    ([DEFAULT, SENSOR_DATA], Reliability.BEST_EFFORT, Durability.VOLATILE),  # mixed: weakest
    ([LATCHED, LATCHED], Reliability.RELIABLE, Durability.TRANSIENT_LOCAL),
    ([LATCHED, DEFAULT], Reliability.RELIABLE, Durability.VOLATILE),
    ([], Reliability.RELIABLE, Durability.VOLATILE),  # no publisher: rosbag2's default
])
def test_recorder_requests_what_every_publisher_can_serve(
        offers: list[QoSProfile], reliability: Reliability, durability: Durability) -> None:
    request = recorder_request(offers)
    assert (request.reliability, request.durability) == (reliability, durability)
    assert (request.history, request.depth) == (History.KEEP_LAST, RECORD_DEPTH)


def test_recorder_keeps_a_deeper_publisher_history() -> None:
    assert recorder_request([DEFAULT.with_depth(5000)]).depth == 5000


def test_player_offers_the_recorded_profile_with_default_history() -> None:
    assert player_offer([to_bag(SENSOR_DATA)]) == SENSOR_DATA.with_depth(10)
    assert player_offer([to_bag(CLOCK)]) == CLOCK.with_depth(10)
    # History and depth do not decide matching: profiles differing only there are "the same".
    same = [to_bag(SENSOR_DATA), to_bag(SENSOR_DATA.with_depth(100))]
    assert player_offer(same) == SENSOR_DATA.with_depth(10)


def test_player_falls_back_to_default_for_mixed_or_missing_offers() -> None:
    assert player_offer([to_bag(SENSOR_DATA), to_bag(DEFAULT)]) == DEFAULT
    assert player_offer([to_bag(LATCHED), to_bag(DEFAULT)]) == DEFAULT
    assert player_offer([]) == DEFAULT
