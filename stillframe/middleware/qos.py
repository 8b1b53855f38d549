"""QoS profiles as rmw defines them (``rmw/qos_profiles.h``), independent of any backend."""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

from stillframe.errors import InputError

#: rmw's "infinite" duration, in nanoseconds (``RMW_DURATION_INFINITE``).
INFINITE_NS = 9_223_372_036_854_775_807


class History(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2
    UNKNOWN = 3


class Reliability(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2
    UNKNOWN = 3


class Durability(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2
    UNKNOWN = 3


class Liveliness(enum.IntEnum):
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
