"""Network faults on the hosts of a :mod:`~stillframe.app.netns_lab` lab: loss, delay, reordering.

Each fault acts on the UDP packets a host receives from the bridge (``iptables -A INPUT -i eth0
-p udp`` in its namespace), so every packet between two loop nodes, and every copy of a
multicast packet, meets it once:

- loss: ``-m statistic --mode random --probability p -j DROP`` (per packet, independent);
- delay, jitter, reordering: ``-j NFQUEUE`` to :mod:`stillframe.app.nfqueue_delay` in the
  namespace (this machine's kernel has no ``tc netem``; :meth:`Fault.netem` gives the netem
  command of the same fault for machines that have it).

Needs root and ``iptables`` (Debian's, on nf_tables).
"""

from __future__ import annotations

import contextlib
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass

from stillframe.app.netns_lab import HOSTS, Lab, host_prefixes, joined, lab
from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT

RULE = ["INPUT", "-i", "eth0", "-p", "udp"]


@dataclass(frozen=True)
class Fault:
    """One row of the fault table: a name and what each host's incoming link does."""

    name: str
    loss: float = 0.0
    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    reorder: float = 0.0

    def netem(self) -> str:
        """The ``tc qdisc add dev IF root netem ...`` arguments of this fault."""
        parts = [f"loss {self.loss * 100:g}%"] if self.loss else []
        if self.delay_ms:
            parts.append(f"delay {self.delay_ms:g}ms"
                         + (f" {self.jitter_ms:g}ms" if self.jitter_ms else ""))
        if self.reorder:
            parts.append(f"reorder {self.reorder * 100:g}%")
        return "netem " + " ".join(parts) if parts else "-"


FAULTS: tuple[Fault, ...] = (
    Fault("none"),
    Fault("loss 1 %", loss=0.01),
    Fault("loss 5 %", loss=0.05),
    Fault("loss 10 %", loss=0.10),
    Fault("loss 30 %", loss=0.30),
    Fault("delay 5 ± 2 ms", delay_ms=5.0, jitter_ms=2.0),
    Fault("reorder 25 %", delay_ms=5.0, reorder=0.25),
)


def fault_named(name: str) -> Fault:
    """The fault of :data:`FAULTS` called ``name`` (spaces ignored); an
    :class:`~stillframe.errors.InputError` listing the names otherwise."""
    for fault in FAULTS:
        if fault.name.replace(" ", "") == name.replace(" ", ""):
            return fault
    raise InputError(f"--fault {name!r}: expected one of " + ", ".join(f.name for f in FAULTS))


def _iptables(namespace: str, *args: str) -> None:
    try:
        subprocess.run(["ip", "netns", "exec", namespace, "iptables", "-w", *args], check=True,
                       capture_output=True, text=True, timeout=20)
    except subprocess.CalledProcessError as exc:
        raise InputError(f"iptables {' '.join(args)} in {namespace}: "
                         f"{exc.stderr.strip() or exc}") from None


def check_tools() -> None:
    """InputError unless ``iptables`` is installed."""
    if shutil.which("iptables") is None:
        raise InputError("network faults need iptables (Debian: apt-get install iptables)")


@contextlib.contextmanager
def applied(lab: Lab, fault: Fault, seed: int = 0) -> Iterator[Fault]:
    """``fault`` on every host of ``lab`` for the block; removed (rules flushed, delay
    processes stopped) however it ends."""
    if fault == Fault(fault.name):
        yield fault
        return
    check_tools()
    namespaces = [lab.namespace(host) for host in HOSTS.values()]
    delays: list[subprocess.Popen] = []
    try:
        for i, ns in enumerate(namespaces):
            if fault.loss:
                _iptables(ns, "-A", *RULE, "-m", "statistic", "--mode", "random",
                          "--probability", f"{fault.loss:g}", "-j", "DROP")
            if fault.delay_ms:
                delays.append(_start_delay(ns, fault, seed + i))
                _iptables(ns, "-A", *RULE, "-j", "NFQUEUE", "--queue-num", "0")
        yield fault
    finally:
        for ns in namespaces:
            subprocess.run(["ip", "netns", "exec", ns, "iptables", "-w", "-F", "INPUT"],
                           capture_output=True, timeout=20)
        for proc in delays:
            proc.terminate()
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(10)
            proc.kill()
            proc.wait()


def _start_delay(namespace: str, fault: Fault, seed: int) -> subprocess.Popen:
    proc = subprocess.Popen(
        ["ip", "netns", "exec", namespace, sys.executable, "-m", "stillframe.app.nfqueue_delay",
         "--delay-ms", f"{fault.delay_ms:g}", "--jitter-ms", f"{fault.jitter_ms:g}",
         "--reorder", f"{fault.reorder:g}", "--seed", str(seed)],
        cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline() if proc.stdout else ""
    if line.strip() != "ready":
        proc.kill()
        _out, err = proc.communicate()
        raise InputError(f"delay queue in {namespace} did not start: {err.strip()[-300:]}")
    return proc


@contextlib.contextmanager
def hosts_if(enabled: bool, prefix: str | None = None,
             fault: str | None = None) -> Iterator[dict[str, list[str]]]:
    """With ``enabled``: a lab joined by this process, the fault named ``fault`` (if any) on
    it, and the node prefixes for :attr:`stillframe.app.launcher.LaunchOptions.hosts`, all
    removed after the block; else no prefixes (every node on this host)."""
    if not enabled:
        if fault is not None or prefix is not None:
            raise InputError("--fault and --netns-prefix need --netns")
        yield {}
        return
    chosen = fault_named(fault) if fault is not None else FAULTS[0]
    with lab(prefix) as made, joined(made), applied(made, chosen):
        yield host_prefixes(made)
