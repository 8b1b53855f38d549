"""QoS profiles as rmw defines them (``rmw/qos_profiles.h``), independent of any backend."""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass, replace

from stillframe.errors import InputError

#: rmw's "infinite" duration, in nanoseconds (``RMW_DURATION_INFINITE``).
INFINITE_NS = 9_223_372_036_854_775_807


class History(enum.IntEnum):
    """``rmw_qos_history_policy_e``: keep the last ``depth`` samples or all of them."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2
    UNKNOWN = 3


class Reliability(enum.IntEnum):
    """``rmw_qos_reliability_policy_e``: resend lost samples (reliable) or not (best effort)."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2
    UNKNOWN = 3


class Durability(enum.IntEnum):
    """``rmw_qos_durability_policy_e``: whether a late-joining reader gets the samples already
    written (transient local) or only new ones (volatile)."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2
    UNKNOWN = 3


class Liveliness(enum.IntEnum):
    """``rmw_qos_liveliness_policy_e``: how a writer shows it is alive, by the middleware
    (automatic) or by publishing on its topic (manual by topic)."""

    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_TOPIC = 3
    UNKNOWN = 4


@dataclass(frozen=True)
class QoSProfile:
    """The QoS policies rmw exposes; durations in nanoseconds (``INFINITE_NS`` = unset)."""

    history: History = History.KEEP_LAST
    depth: int = 10
    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    deadline_ns: int = INFINITE_NS
    lifespan_ns: int = INFINITE_NS
    liveliness: Liveliness = Liveliness.AUTOMATIC
    liveliness_lease_duration_ns: int = INFINITE_NS

    def with_depth(self, depth: int) -> QoSProfile:
        """The same profile with another KEEP_LAST depth."""
        return replace(self, history=History.KEEP_LAST, depth=depth)


#: ``rmw_qos_profile_sensor_data``.
SENSOR_DATA = QoSProfile(depth=5, reliability=Reliability.BEST_EFFORT)
#: ``rmw_qos_profile_default``.
DEFAULT = QoSProfile()
#: rclcpp's ``ClockQoS`` for ``/clock``.
CLOCK = QoSProfile(depth=1, reliability=Reliability.BEST_EFFORT)
#: ``rmw_qos_profile_parameters``.
PARAMETERS = QoSProfile(depth=1000)

PROFILES: dict[str, QoSProfile] = {
    "sensor_data": SENSOR_DATA,
    "default": DEFAULT,
    "clock": CLOCK,
    "parameters": PARAMETERS,
}


def as_profile(qos: QoSProfile | str | int) -> QoSProfile:
    """A profile from a profile, a profile name (``PROFILES``) or, like rclpy, a KEEP_LAST depth."""
    if isinstance(qos, QoSProfile):
        return qos
    if isinstance(qos, bool):
        raise InputError(f"not a QoS profile: {qos!r}")
    if isinstance(qos, int):
        if qos < 1:
            raise InputError(f"QoS depth must be >= 1, got {qos}")
        return DEFAULT.with_depth(qos)
    if qos in PROFILES:
        return PROFILES[qos]
    raise InputError(f"unknown QoS profile {qos!r} (one of {', '.join(PROFILES)})")


#: Depth of the recorder's subscriptions: deep enough that a slow disk loses nothing.
RECORD_DEPTH = 1000


def recorder_request(offers: Sequence[QoSProfile]) -> QoSProfile:
    """The recorder's subscription QoS (rosbag2's ``adapt_request_to_offers``): RELIABLE and
    TRANSIENT_LOCAL only if every publisher offers them (a stricter request would not match the
    others). History KEEP_LAST with the deepest offered depth, but at least ``RECORD_DEPTH``
    (rosbag2 takes the deepest offer; a Python recorder needs more room when the disk stalls)."""
    if not offers:
        return DEFAULT.with_depth(RECORD_DEPTH)
    reliable = all(p.reliability == Reliability.RELIABLE for p in offers)
    transient = all(p.durability == Durability.TRANSIENT_LOCAL for p in offers)
    return QoSProfile(
        depth=max(RECORD_DEPTH, *(p.depth for p in offers)),
        reliability=Reliability.RELIABLE if reliable else Reliability.BEST_EFFORT,
        durability=Durability.TRANSIENT_LOCAL if transient else Durability.VOLATILE,
    )


def viewer_request(offers: Sequence[QoSProfile]) -> QoSProfile:
    """A live viewer's subscription QoS: :func:`recorder_request` but BEST_EFFORT always. A
    reliable reader makes each publisher track it (heartbeats, acknowledgements, repairs) on the
    loop's own path; a viewer would rather miss a sample than cost the loop time."""
    return replace(recorder_request(offers), reliability=Reliability.BEST_EFFORT)
