"""QoS between the middleware and bags: conversion to and from rosbag2's metadata form, and
rosbag2's rules for adapting a recorder's request and a player's offer to recorded offers
(``rosbag2_transport/qos.cpp``: ``adapt_request_to_offers``, ``adapt_offer_to_recorded_offers``).
"""

from __future__ import annotations

from collections.abc import Sequence

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime as BagTime

from stillframe.middleware.qos import (
    DEFAULT,
    INFINITE_NS,
    Durability,
    History,
    Liveliness,
    QoSProfile,
    Reliability,
)

#: rmw's infinite duration as rosbag2 writes it: {sec: 9223372036, nsec: 854775807}.
_INFINITE = BagTime(*divmod(INFINITE_NS, 1_000_000_000))
#: "Infinite" as Fast DDS and Connext reported it before rmw had RMW_DURATION_INFINITE (bags
#: from Foxy); rosbag2 reads both as infinite.
_FOXY_INFINITE = {(0x7FFFFFFF, 0xFFFFFFFF), (0x7FFFFFFF, 0x7FFFFFFF)}


def _to_time(ns: int) -> BagTime:
    return BagTime(*divmod(ns, 1_000_000_000)) if ns < INFINITE_NS else _INFINITE


def _from_time(t: BagTime) -> int:
    if (t.sec, t.nsec) in _FOXY_INFINITE:
        return INFINITE_NS
    return min(t.sec * 1_000_000_000 + t.nsec, INFINITE_NS)


def to_bag(profile: QoSProfile) -> Qos:
    """rosbag2's form of a middleware profile (for ``offered_qos_profiles``)."""
    return Qos(
        QosHistory(int(profile.history)), profile.depth,
        QosReliability(int(profile.reliability)), QosDurability(int(profile.durability)),
        _to_time(profile.deadline_ns), _to_time(profile.lifespan_ns),
        QosLiveliness(int(profile.liveliness)), _to_time(profile.liveliness_lease_duration_ns),
        False,
    )


def _member(enum: type, value: object, fallback: object) -> object:
    name = getattr(value, "name", "")
    return enum.__members__.get(name, fallback)


def from_bag(qos: Qos) -> QoSProfile:
    """The middleware profile of a recorded offer; policies rmw cannot express (UNKNOWN,
    BEST_AVAILABLE) fall back to the default profile's."""
    return QoSProfile(
        history=_member(History, qos.history, DEFAULT.history),
        depth=qos.depth or DEFAULT.depth,
        reliability=_member(Reliability, qos.reliability, DEFAULT.reliability),
        durability=_member(Durability, qos.durability, DEFAULT.durability),
        deadline_ns=_from_time(qos.deadline), lifespan_ns=_from_time(qos.lifespan),
        liveliness=_member(Liveliness, qos.liveliness, DEFAULT.liveliness),
        liveliness_lease_duration_ns=_from_time(qos.liveliness_lease_duration),
    )


def _compatibility(p: QoSProfile) -> tuple[object, ...]:
    """The policies that decide whether endpoints match (history and lifespan do not)."""
    return (p.reliability, p.durability, p.deadline_ns, p.liveliness,
            p.liveliness_lease_duration_ns)


def player_offer(recorded: Sequence[Qos]) -> QoSProfile:
    """The player's publisher QoS (rosbag2's ``adapt_offer_to_recorded_offers``): the recorded
    offer with the default history if all recorded publishers offered effectively the same
    profile, else the default profile."""
    profiles = [from_bag(q) for q in recorded]
    if profiles and all(_compatibility(p) == _compatibility(profiles[0]) for p in profiles):
        return profiles[0].with_depth(DEFAULT.depth)
    return DEFAULT
