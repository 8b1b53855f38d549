"""Skip conditions and a UDP probe for the network-namespace tests (root, iproute2, iptables)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from stillframe.locations import REPO_ROOT


def netns_skip_reason(tools: tuple[str, ...] = ("ip",)) -> str | None:
    """Why network-namespace tests cannot run here (None: they can)."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    missing = [tool for tool in tools if shutil.which(tool) is None]
    if missing:
        return f"not installed: {', '.join(missing)}"
    probe = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, timeout=20)
    return None if probe.returncode == 0 else f"`ip netns` does not work: {probe.stderr.strip()}"


def require_netns(*tools: str) -> None:
    """Skip the test unless root, ``ip netns`` and ``tools`` are available."""
    reason = netns_skip_reason(("ip", *tools))
    if reason:
        pytest.skip(reason)


RECEIVER = """
import socket, struct, sys, time
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.bind((sys.argv[1], 5000)); s.settimeout(2.0)
print("ready", flush=True)
while True:
    try:
        data = s.recv(64)
    except socket.timeout:
        break
    index, sent = struct.unpack("=Id", data)
    print(index, time.monotonic() - sent)
"""

SENDER = """
import socket, struct, sys, time
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
for i in range(int(sys.argv[2])):
    s.sendto(struct.pack("=Id", i, time.monotonic()), (sys.argv[1], 5000))
    if i % 5 == 4:
        time.sleep(0.005)
"""


def udp_probe(sender_ns: str, receiver_ns: str, address: str,
              count: int) -> list[tuple[int, float]]:
    """``count`` datagrams from ``sender_ns`` to ``address`` in ``receiver_ns``, in bursts of
    five back to back, 5 ms between bursts:
    (index, one-way delay in s on the shared monotonic clock) of each received, in order of
    arrival."""
    receiver = subprocess.Popen(["ip", "netns", "exec", receiver_ns, sys.executable, "-c",
                                 RECEIVER, address], stdout=subprocess.PIPE, text=True,
                                cwd=REPO_ROOT)
    assert receiver.stdout is not None and receiver.stdout.readline().strip() == "ready"
    subprocess.run(["ip", "netns", "exec", sender_ns, sys.executable, "-c", SENDER, address,
                    str(count)], check=True, timeout=120)
    out, _ = receiver.communicate(timeout=60)
    return [(int(i), float(d)) for i, d in (line.split() for line in out.splitlines())]
