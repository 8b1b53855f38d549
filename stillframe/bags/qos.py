"""QoS between the middleware and bags: conversion to and from rosbag2's metadata form (the
profiles as rosbag2 writes them into ``metadata.yaml`` v9 and into each MCAP channel), and
rosbag2's rules for adapting a recorder's request and a player's offer to recorded offers
(``rosbag2_transport/qos.cpp``: ``adapt_request_to_offers``, ``adapt_offer_to_recorded_offers``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from enum import IntEnum
from typing import Any

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


#: the enumerated policies of a profile as rosbag2 writes them (lower-case names)
_POLICIES: dict[str, type[IntEnum]] = {
    "history": QosHistory, "reliability": QosReliability, "durability": QosDurability,
    "liveliness": QosLiveliness}
_TIMES = ("deadline", "lifespan", "liveliness_lease_duration")


def qos_to_yaml(profiles: Sequence[Qos]) -> list[dict[str, Any]]:
    """Profiles as rosbag2 writes them in ``metadata.yaml`` v9 (and, as YAML text, in an MCAP
    channel's ``offered_qos_profiles``): policy names in lower case, times as sec/nsec."""
    return [{
        "history": q.history.name.lower(), "depth": q.depth,
        "reliability": q.reliability.name.lower(), "durability": q.durability.name.lower(),
        "deadline": {"sec": q.deadline.sec, "nsec": q.deadline.nsec},
        "lifespan": {"sec": q.lifespan.sec, "nsec": q.lifespan.nsec},
        "liveliness": q.liveliness.name.lower(),
        "liveliness_lease_duration": {"sec": q.liveliness_lease_duration.sec,
                                      "nsec": q.liveliness_lease_duration.nsec},
        "avoid_ros_namespace_conventions": q.avoid_ros_namespace_conventions,
    } for q in profiles]


def qos_from_yaml(items: list[Any], error: Callable[[str], Exception]) -> list[Qos]:
    """Profiles from their rosbag2 form (:func:`qos_to_yaml`; policies also as numbers, as
    rosbag2 before v9 wrote them); ``error(text)`` is raised naming the first field that is
    missing or of the wrong type."""

    def whole(where: str, value: Any) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**64:
            raise error(f"{where}: expected an integer >= 0, got {value!r}"[:160])
        return value

    def policy(where: str, enum: type[IntEnum], value: Any) -> Any:
        if isinstance(value, str) and value.upper() in enum.__members__:
            return enum.__members__[value.upper()]
        if isinstance(value, int) and not isinstance(value, bool) \
                and value in {m.value for m in enum}:
            return enum(value)
        raise error(f"{where}: expected one of {', '.join(n.lower() for n in enum.__members__)}, "
                    f"got {value!r}"[:200])

    profiles = []
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise error(f"[{i}]: expected a mapping, got {item!r}"[:160])
        missing = [k for k in (*_POLICIES, "depth", *_TIMES, "avoid_ros_namespace_conventions")
                   if k not in item]
        if missing:
            raise error(f"[{i}]: missing key {missing[0]!r}")
        times = {}
        for key in _TIMES:
            value = item[key]
            if not isinstance(value, dict) or not {"sec", "nsec"} <= value.keys():
                raise error(f"[{i}].{key}: expected a mapping of sec and nsec, got {value!r}"[:160])
            times[key] = BagTime(whole(f"[{i}].{key}.sec", value["sec"]),
                                 whole(f"[{i}].{key}.nsec", value["nsec"]))
        avoid = item["avoid_ros_namespace_conventions"]
        if not isinstance(avoid, bool):
            raise error(f"[{i}].avoid_ros_namespace_conventions: expected true or false, got "
                        f"{avoid!r}"[:160])
        enums = {key: policy(f"[{i}].{key}", enum, item[key]) for key, enum in _POLICIES.items()}
        profiles.append(Qos(enums["history"], whole(f"[{i}].depth", item["depth"]),
                            enums["reliability"], enums["durability"], times["deadline"],
                            times["lifespan"], enums["liveliness"],
                            times["liveliness_lease_duration"], avoid))
    return profiles


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
