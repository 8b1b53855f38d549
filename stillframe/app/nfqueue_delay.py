"""Delay and reorder packets in user space through a netfilter queue (``NFQUEUE``).

What ``tc netem delay D J`` / ``delay D reorder R`` do, for kernels built without netem (this
machine's: ``CONFIG_NET_SCH_NETEM`` is not set). An iptables rule hands each packet to queue N;
this process, bound to it over netlink (``NETLINK_NETFILTER``, the ``nfnetlink_queue``
messages of ``linux/netfilter/nfnetlink_queue.h``), gives each packet its release time and
accepts it then. Verdicts may come in any order, so packets whose delays cross are reordered:

- ``--delay-ms D --jitter-ms J``: each packet waits D + U(−J, J) ms (netem's default uniform
  jitter);
- ``--reorder R``: with probability R a packet goes at once, the others wait D ms (netem's
  ``delay D reorder R``, without correlation).

Run it in the namespace of the rule: ``ip netns exec NS python -m stillframe.app.nfqueue_delay``.
It prints ``ready`` once bound and, on SIGTERM or SIGINT, ``queued N`` after releasing every
packet it holds.
"""

from __future__ import annotations

import argparse
import heapq
import random
import select
import signal
import socket
import struct
import sys
import time
from dataclasses import dataclass

NETLINK_NETFILTER = 12
NETLINK_NO_ENOBUFS = 5
SOL_NETLINK = 270
NFNL_SUBSYS_QUEUE = 3
NFQNL_MSG_PACKET, NFQNL_MSG_VERDICT, NFQNL_MSG_CONFIG = 0, 1, 2
NFQA_PACKET_HDR = 1
NFQA_VERDICT_HDR = 2
NFQA_CFG_CMD, NFQA_CFG_PARAMS = 1, 2
NFQNL_CFG_CMD_BIND, NFQNL_CFG_CMD_UNBIND = 1, 2
NFQNL_COPY_META = 1
NLM_F_REQUEST, NLM_F_ACK = 1, 4
NLMSG_ERROR = 2
NF_ACCEPT = 1
_NLMSG = struct.Struct("=IHHII")
_NFGEN = struct.Struct("=BBH")   # family, version, res_id (big-endian queue number, packed below)


@dataclass(frozen=True)
class DelayModel:
    """Per-packet delay in seconds (module docstring)."""

    delay_s: float
    jitter_s: float = 0.0
    reorder: float = 0.0

    def draw(self, rng: random.Random) -> float:
        """One packet's delay [s] drawn from ``rng``: zero with probability ``reorder`` (sent at
        once, ahead of the held ones), else ``delay_s`` plus a uniform jitter within ± ``jitter_s``,
        never negative."""
        if self.reorder and rng.random() < self.reorder:
            return 0.0
        return max(0.0, self.delay_s + (rng.uniform(-self.jitter_s, self.jitter_s)
                                        if self.jitter_s else 0.0))


def _attr(kind: int, payload: bytes) -> bytes:
    length = 4 + len(payload)
    return struct.pack("=HH", length, kind) + payload + b"\0" * (-length % 4)


def _message(kind: int, queue: int, attrs: bytes, flags: int = NLM_F_REQUEST, seq: int = 0,
             family: int = socket.AF_UNSPEC) -> bytes:
    body = struct.pack("=BB", family, 0) + struct.pack("!H", queue) + attrs
    return _NLMSG.pack(_NLMSG.size + len(body), (NFNL_SUBSYS_QUEUE << 8) | kind, flags, seq,
                       0) + body


def _attributes(data: bytes) -> dict[int, bytes]:
    attrs, offset = {}, 0
    while offset + 4 <= len(data):
        length, kind = struct.unpack_from("=HH", data, offset)
        if length < 4:
            break
        attrs[kind & 0x7FFF] = data[offset + 4: offset + length]
        offset += (length + 3) & ~3
    return attrs


class Queue:
    """One netfilter queue bound on a netlink socket."""

    def __init__(self, number: int) -> None:
        self.number = number
        self.sock = socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, NETLINK_NETFILTER)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.setsockopt(SOL_NETLINK, NETLINK_NO_ENOBUFS, 1)
        self.sock.bind((0, 0))
        self._config(_attr(NFQA_CFG_CMD, struct.pack("!BxH", NFQNL_CFG_CMD_BIND, 0)))
        self._config(_attr(NFQA_CFG_PARAMS, struct.pack("!IB", 0, NFQNL_COPY_META)))

    def _config(self, attrs: bytes) -> None:
        self.sock.send(_message(NFQNL_MSG_CONFIG, self.number, attrs, NLM_F_REQUEST | NLM_F_ACK))
        reply = self.sock.recv(65536)
        _len, kind, _flags, _seq, _pid = _NLMSG.unpack_from(reply)
        if kind == NLMSG_ERROR and (code := struct.unpack_from("=i", reply, _NLMSG.size)[0]):
            raise OSError(-code, f"nfqueue {self.number}: config refused")

    def packet_ids(self) -> list[int]:
        """The ids of the packets in the next datagram from the kernel."""
        data, ids, offset = self.sock.recv(1 << 20), [], 0
        while offset + _NLMSG.size <= len(data):
            length, kind, _flags, _seq, _pid = _NLMSG.unpack_from(data, offset)
            if length < _NLMSG.size:
                break
            if kind == (NFNL_SUBSYS_QUEUE << 8) | NFQNL_MSG_PACKET:
                attrs = _attributes(data[offset + _NLMSG.size + _NFGEN.size: offset + length])
                if NFQA_PACKET_HDR in attrs:
                    ids.append(struct.unpack_from("!I", attrs[NFQA_PACKET_HDR])[0])
            offset += (length + 3) & ~3
        return ids

    def accept(self, packet_id: int) -> None:
        """Send the kernel the verdict NF_ACCEPT for ``packet_id``: the packet goes on."""
        self.sock.send(_message(NFQNL_MSG_VERDICT, self.number,
                                _attr(NFQA_VERDICT_HDR, struct.pack("!II", NF_ACCEPT, packet_id))))

    def close(self) -> None:
        """Unbind the queue and close the netlink socket."""
        try:
            self._config(_attr(NFQA_CFG_CMD, struct.pack("!BxH", NFQNL_CFG_CMD_UNBIND, 0)))
        finally:
            self.sock.close()


def serve(queue: Queue, model: DelayModel, rng: random.Random) -> int:
    """Delay every packet of ``queue`` by ``model`` until SIGTERM/SIGINT; the packets seen."""
    stop = False

    def on_signal(_signum: int, _frame: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    held: list[tuple[float, int]] = []
    seen = 0
    while not stop:
        now = time.monotonic()
        while held and held[0][0] <= now:
            queue.accept(heapq.heappop(held)[1])
        timeout = max(0.0, held[0][0] - now) if held else 0.2
        try:
            readable = select.select([queue.sock], [], [], timeout)[0]
        except InterruptedError:
            continue
        if readable:
            for packet_id in queue.packet_ids():
                seen += 1
                heapq.heappush(held, (time.monotonic() + model.draw(rng), packet_id))
    for _due, packet_id in sorted(held):
        queue.accept(packet_id)
    return seen


def main(argv: list[str] | None = None) -> int:
    """Bind the netfilter queue ``--queue``, print ``ready``, hold each packet for its drawn delay
    until SIGTERM or SIGINT (:func:`serve`), then release the held ones and print ``queued N``
    (the packets seen); exit code 0."""
    parser = argparse.ArgumentParser(prog="python -m stillframe.app.nfqueue_delay",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--queue", type=int, default=0)
    parser.add_argument("--delay-ms", type=float, required=True)
    parser.add_argument("--jitter-ms", type=float, default=0.0)
    parser.add_argument("--reorder", type=float, default=0.0, help="share sent at once (0..1)")
    parser.add_argument("--seed", type=int, default=None)
    args = parser.parse_args(argv)
    queue = Queue(args.queue)
    print("ready", flush=True)
    try:
        seen = serve(queue, DelayModel(args.delay_ms * 1e-3, args.jitter_ms * 1e-3, args.reorder),
                     random.Random(args.seed))
    finally:
        queue.close()
    print(f"queued {seen}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
