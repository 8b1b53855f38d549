"""Three hosts on one host: a network namespace per loop node, joined by veth pairs to a bridge.

The CI stand-in for three machines on a lab network. Needs root and iproute2.
For a prefix P (letters and digits, at most 10, unique per run so that parallel runs never
clash) it makes:

- namespaces ``P-sim``, ``P-est``, ``P-ctl`` (the hosts) and ``P-br`` (the switch);
- in ``P-br`` a Linux bridge ``br0`` without multicast snooping (a plain switch: multicast is
  flooded to every port), with one port per host (``sim``, ``est``, ``ctl``) and ``obs``;
- in each host an ``eth0`` at 10.a.b.1/2/3 (one free /24 of 10.213.0.0/16), ``lo`` up and the
  multicast route 224.0.0.0/4 on ``eth0``: DDS discovery is the default, multicast over the
  bridge;
- in this (the root) namespace ``Ph``, the peer of ``obs``, at 10.a.b.254: the launcher's own
  node (status line, observers, recorder) joins the network there, on that interface only.

Deleting the four namespaces removes every veth and the bridge with them (a veth pair dies
with either end), so :func:`down` is ``ip netns del`` of each; :func:`lab` always calls it.
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import re
import subprocess
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from stillframe.errors import InputError

#: the host of each loop node, in the launcher's names
HOSTS: dict[str, str] = {"sim_node": "sim", "estimator_node": "est", "controller_node": "ctl"}
BRIDGE_HOST = "br"
#: the pool the lab's /24 comes from
POOL = ipaddress.ip_network("10.213.0.0/16")
OBSERVER_ADDRESS = 254
_PREFIX = re.compile(r"[a-z][a-z0-9]{0,9}")


@dataclass(frozen=True)
class Lab:
    """A lab made by :func:`up`: its prefix and its /24."""

    prefix: str
    subnet: ipaddress.IPv4Network

    def namespace(self, host: str) -> str:
        """The network namespace of ``host`` in this lab (``P-sim`` for prefix ``P``)."""
        return f"{self.prefix}-{host}"

    @property
    def observer_interface(self) -> str:
        """The root namespace's interface on the bridge."""
        return f"{self.prefix}h"

    def address(self, host: str) -> ipaddress.IPv4Address:
        """The IPv4 address of ``host`` (or of the observer, ``obs``) on the lab's bridge subnet."""
        index = [*HOSTS.values(), "obs"].index(host)
        return self.subnet[index + 1 if host != "obs" else OBSERVER_ADDRESS]

    def prefix_of(self, node: str) -> list[str]:
        """The command prefix that runs ``node`` on its host: ``ip netns exec P-HOST``; the
        node's DDS runs on its own defaults there (``CYCLONEDDS_URI`` of the observer removed,
        Fast DDS on UDP only, so that no shared memory crosses between the hosts)."""
        return ["ip", "netns", "exec", self.namespace(HOSTS[node]), "env", "-u", "CYCLONEDDS_URI",
                "FASTDDS_BUILTIN_TRANSPORTS=UDPv4"]

    def observer_cyclone_config(self) -> str:
        """``CYCLONEDDS_URI`` for a participant in the root namespace: the lab's interface."""
        return ("<CycloneDDS><Domain><General><Interfaces>"
                f'<NetworkInterface name="{self.observer_interface}" multicast="true"/>'
                "</Interfaces></General></Domain></CycloneDDS>")


def check_prefix(prefix: str) -> str:
    """``prefix`` if it makes valid namespace and interface names (a lower-case letter and up to 9
    letters or digits), else an :class:`~stillframe.errors.InputError`."""
    if not _PREFIX.fullmatch(prefix):
        raise InputError(f"--prefix {prefix!r}: expected a lower-case letter and up to 9 more "
                         "letters or digits (interface names have at most 15 characters)")
    return prefix


def default_prefix() -> str:
    """``sf`` and this process's id: unique among running labs."""
    return f"sf{os.getpid()}"


def _ip(*args: str) -> None:
    try:
        subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=20)
    except FileNotFoundError:
        raise InputError("network namespaces need iproute2 ('ip' not found)") from None
    except subprocess.CalledProcessError as exc:
        raise InputError(f"ip {' '.join(args)}: {exc.stderr.strip() or exc}") from None


def namespaces() -> list[str]:
    """The names of every network namespace (``ip netns list``)."""
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, timeout=20)
    return [line.split()[0] for line in out.stdout.splitlines() if line.strip()]


def free_subnet(prefix: str) -> ipaddress.IPv4Network:
    """A /24 of :data:`POOL` that no route of this namespace overlaps, starting from one the
    prefix picks (so that parallel labs start apart)."""
    routes = subprocess.run(["ip", "-4", "route", "show", "table", "all"], capture_output=True,
                            text=True, timeout=20).stdout
    used = []
    for line in routes.splitlines():
        with contextlib.suppress(ValueError):
            used.append(ipaddress.ip_network(line.split()[0].replace("default", "0.0.0.0/0"),
                                             strict=False))
    subnets = list(POOL.subnets(new_prefix=24))[1:]
    start = sum(map(ord, prefix)) * 7919 % len(subnets)
    for candidate in subnets[start:] + subnets[:start]:
        if not any(candidate.overlaps(u) and u.prefixlen > 0 for u in used):
            return candidate
    raise InputError(f"no free /24 left in {POOL} for a network lab")


def up(prefix: str) -> Lab:
    """Make the lab (module docstring); on any failure remove what was made and raise."""
    check_prefix(prefix)
    if os.geteuid() != 0:
        raise InputError("network namespaces need root")
    taken = [n for n in namespaces() if n.startswith(f"{prefix}-")]
    if taken:
        raise InputError(f"a lab with prefix {prefix!r} exists ({', '.join(taken)}); "
                         f"remove it with `stillframe netns down --prefix {prefix}`")
    lab = Lab(prefix, free_subnet(prefix))
    bridge = lab.namespace(BRIDGE_HOST)
    try:
        for host in (*HOSTS.values(), BRIDGE_HOST):
            _ip("netns", "add", lab.namespace(host))
            _ip("-n", lab.namespace(host), "link", "set", "lo", "up")
        _ip("-n", bridge, "link", "add", "br0", "type", "bridge", "mcast_snooping", "0")
        _ip("-n", bridge, "link", "set", "br0", "up")
        for host in HOSTS.values():
            ns = lab.namespace(host)
            _ip("link", "add", "eth0", "netns", ns, "type", "veth", "peer", "name", host,
                "netns", bridge)
            _ip("-n", ns, "addr", "add", f"{lab.address(host)}/24", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "up", "multicast", "on")
            _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")
            _ip("-n", bridge, "link", "set", host, "master", "br0", "up")
        _ip("link", "add", lab.observer_interface, "type", "veth", "peer", "name", "obs",
            "netns", bridge)
        _ip("-n", bridge, "link", "set", "obs", "master", "br0", "up")
        _ip("addr", "add", f"{lab.address('obs')}/24", "dev", lab.observer_interface)
        _ip("link", "set", lab.observer_interface, "up", "multicast", "on")
    except BaseException:
        down(prefix)
        raise
    return lab


def down(prefix: str) -> list[str]:
    """Delete every namespace of the lab (with its veths and bridge) and the root namespace's
    interface if it survived; the namespaces deleted."""
    check_prefix(prefix)
    gone = []
    for name in namespaces():
        if name.startswith(f"{prefix}-") and name[len(prefix) + 1:] in (*HOSTS.values(),
                                                                        BRIDGE_HOST):
            subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=20)
            gone.append(name)
    subprocess.run(["ip", "link", "del", f"{prefix}h"], capture_output=True, timeout=20)
    return gone


@contextlib.contextmanager
def lab(prefix: str | None = None) -> Iterator[Lab]:
    """:func:`up`, then :func:`down` however the block ends."""
    made = up(prefix or default_prefix())
    try:
        yield made
    finally:
        down(made.prefix)


def observer_environment(made: Lab) -> dict[str, str]:
    """What this process's own DDS participant needs to join the lab from the root namespace:
    the default discovery range (multicast) on the lab's interface only, on the ``dds``
    backend (Cyclone, which that interface setting is for; also the nodes' default backend)."""
    return {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "STILLFRAME_RMW": "dds",
            "CYCLONEDDS_URI": made.observer_cyclone_config()}


@contextlib.contextmanager
def joined(made: Lab) -> Iterator[Lab]:
    """This process's environment set to :func:`observer_environment` for the block (the DDS
    participant created in it, and every child started from it, join the lab)."""
    saved = {key: os.environ.get(key) for key in observer_environment(made)}
    os.environ.update(observer_environment(made))
    try:
        yield made
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def host_prefixes(made: Lab, nodes: Sequence[str] = tuple(HOSTS)) -> dict[str, list[str]]:
    """The command prefix of each node (:meth:`Lab.prefix_of`)."""
    return {node: made.prefix_of(node) for node in nodes}

