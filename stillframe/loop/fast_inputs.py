"""Subscriptions of the loop nodes that read their values straight from the CDR bytes.

The hot path of the estimator and the controller: a raw subscription checks the sample's writer
against the topic's :class:`stillframe.loop.writer_gate.WriterGate` (the run's token in its
bytes, or a set lookup of its writer), hands the bytes to a
:class:`stillframe.contract.codecs.TopicReader` (a few fields unpacked in place when the layout is
the stack's own, ``rosbags`` otherwise), and the handler gets the values; bytes that are no valid
message are counted in the node's ``malformed``
(:attr:`stillframe.middleware.interface.Node.malformed`), as the decoding subscriptions count them.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any

from stillframe.contract.codecs import TopicReader
from stillframe.loop.writer_gate import WriterGate
from stillframe.middleware import api


def reading(topic: str, reader: TopicReader, handler: Callable[..., None],
            gate: WriterGate, malformed: Counter[str]) -> Callable[..., None]:
    """A raw subscription callback: ``handler(*reader.read(cdr))`` for the samples ``gate``
    admits; bytes that do not read are counted in ``malformed``."""
    read, admits = reader.read, gate.admits

    def callback(cdr: bytes, info: api.MessageInfo) -> None:
        if not admits(info.publisher_gid, info.publication_sequence, cdr):
            return
        values = read(cdr)
        if values is None:
            malformed[topic] += 1
        else:
            handler(*values)

    return callback


def subscribe(node: api.Node, type_name: str, topic: str, qos: Any, reader: TopicReader,
              handler: Callable[..., None], gate: WriterGate) -> Any:
    """Subscribe ``topic`` raw, handing ``reader``'s values from the writers ``gate`` admits
    to ``handler``."""
    return node.create_subscription(
        type_name, topic, reading(topic, reader, handler, gate, node.malformed), qos, raw=True)
