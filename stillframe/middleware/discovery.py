"""Discovery settings from ROS 2's environment, with the meaning ``rmw_cyclonedds_cpp`` gives them
in Jazzy (``check_create_domain`` in its ``rmw_node.cpp``).

- ``ROS_AUTOMATIC_DISCOVERY_RANGE``: ``SUBNET`` (the default: multicast on the chosen interface,
  plus the static peers), ``LOCALHOST`` (no multicast; unicast discovery of ``localhost`` and the
  static peers; without static peers, on the loopback interface only), ``OFF`` (no multicast,
  no peers, and a domain tag private to the process, so nothing outside it is discovered) or
  ``SYSTEM_DEFAULT`` (Cyclone's own settings untouched).
- ``ROS_STATIC_PEERS``: semicolon-separated hosts, used with ``SUBNET`` and ``LOCALHOST``.
- ``ROS_LOCALHOST_ONLY=1`` (deprecated in Jazzy, still honoured by rcl) means ``LOCALHOST``.
- ``CYCLONEDDS_URI``: appended after these settings, so a user's own configuration wins.

An unknown range is bad input (rcl only warns and assumes ``LOCALHOST``; we refuse to guess).
"""

from __future__ import annotations

import os
from enum import Enum

from stillframe.config.environment import DISCOVERY_RANGES, is_set, value

RANGE_ENV = "ROS_AUTOMATIC_DISCOVERY_RANGE"
PEERS_ENV = "ROS_STATIC_PEERS"
#: Participants rmw_cyclonedds_cpp probes per host with unicast discovery.
MAX_AUTO_PARTICIPANT_INDEX = 32
#: LOCALHOST without static peers also binds Cyclone to the loopback interface. rmw_cyclonedds_cpp
#: leaves the interface to Cyclone (the host's first multicast-capable one), but then Cyclone does
#: not talk to Fast DDS nodes under LOCALHOST, which restrict themselves to loopback: their
#: samples then reach Cyclone in some start orders only. Bound to loopback, every order works.
LOOPBACK_INTERFACE = ('<Interfaces><NetworkInterface address="127.0.0.1"/>'
                      '<NetworkInterface autodetermine="true" multicast="false"/></Interfaces>')


#: the ranges, each its own value (declared once, with the variable, in config.environment)
DiscoveryRange = Enum("DiscoveryRange", [(name, name) for name in DISCOVERY_RANGES])


def discovery_range() -> DiscoveryRange:
    """The range the environment asks for (``SUBNET`` when unset; ``LOCALHOST`` with
    ``ROS_LOCALHOST_ONLY=1``); InputError for a range there is not."""
    if not is_set(RANGE_ENV) and value("ROS_LOCALHOST_ONLY") == "1":
        return DiscoveryRange.LOCALHOST
    return DiscoveryRange(value(RANGE_ENV))


#: the highest domain id rcl takes (its UDP ports must fit: rmw's 0..232)


def domain_id() -> int:
    """``ROS_DOMAIN_ID`` (default 0); InputError unless an integer 0..
    :data:`stillframe.config.environment.MAX_DOMAIN_ID`."""
    return int(value("ROS_DOMAIN_ID"))


def static_peers() -> list[str]:
    """``ROS_STATIC_PEERS`` as a list of hosts."""
    return [p.strip() for p in value(PEERS_ENV).split(";") if p.strip()]


def cyclone_config() -> str:
    """The configuration for ``cyclonedds.domain.Domain``: rmw's fragment for the discovery
    range, then ``CYCLONEDDS_URI`` (Cyclone reads a comma-separated list; later entries win)."""
    chosen = discovery_range()
    peers = static_peers()
    fragment = ""
    if chosen is DiscoveryRange.OFF:
        fragment = (
            "<General><AllowMulticast>false</AllowMulticast></General>"
            "<Discovery><ParticipantIndex>none</ParticipantIndex>"
            f"<Tag>ros_discovery_off_{os.getpid()}</Tag></Discovery>"
        )
    elif chosen is DiscoveryRange.LOCALHOST or (chosen is DiscoveryRange.SUBNET and peers):
        localhost = chosen is DiscoveryRange.LOCALHOST
        addresses = (["localhost"] if localhost else []) + peers
        general = ""
        if localhost:
            general = "<General>" + (LOOPBACK_INTERFACE if not peers else "") + (
                "<AllowMulticast>false</AllowMulticast></General>")
        fragment = (
            general
            + "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
            f"<MaxAutoParticipantIndex>{MAX_AUTO_PARTICIPANT_INDEX}</MaxAutoParticipantIndex>"
            "<Peers>" + "".join(f'<Peer address="{a}"/>' for a in addresses) + "</Peers>"
            "</Discovery>"
        )
    parts = [f"<CycloneDDS><Domain>{fragment}</Domain></CycloneDDS>"] if fragment else []
    user = value("CYCLONEDDS_URI")
    if user:
        parts.append(user)
    return ",".join(parts)
