"""Subscriptions of the loop nodes that read their values straight from the CDR bytes.

The hot path of the estimator, controller and simulator: a raw subscription hands the bytes to a
:class:`stillframe.contract.codecs.TopicReader` (a few fields unpacked in place when the layout is
the stack's own, ``rosbags`` otherwise), and the handler gets the values; bytes that are no valid
message are counted in ``api.MALFORMED``, as the decoding subscriptions count them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from stillframe.contract.codecs import TopicReader
from stillframe.middleware import api


def reading(topic: str, reader: TopicReader, handler: Callable[..., None]) -> Callable[..., None]:
    """A raw subscription callback: ``handler(*reader.read(cdr))``."""
    read = reader.read

    def callback(cdr: bytes, info: Any) -> None:
        values = read(cdr)
        if values is None:
            api.MALFORMED[topic] += 1
        else:
            handler(*values)

    return callback


def subscribe(node: api.Node, type_name: str, topic: str, qos: Any, reader: TopicReader,
              handler: Callable[..., None]) -> Any:
    """Subscribe ``topic`` raw, handing ``reader``'s values to ``handler``."""
    return node.create_subscription(type_name, topic, reading(topic, reader, handler), qos,
                                    raw=True)
