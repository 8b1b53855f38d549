"""``adaptation/events`` (:data:`~stillframe.contract.topics.ADAPTATION_EVENTS`): what the
adaptation decided (:mod:`stillframe.loop.adaptation`), as ``diagnostic_msgs/DiagnosticArray``.

One message per event, stamped with the sample that decided it; one ``DiagnosticStatus`` whose
``values`` carry the event's record as JSON text, ``kind`` and ``t`` first. A DiagnosticArray
for the reasons of ``structure_events`` (:mod:`stillframe.contract.structure_events`): stamped in
the loop's time, printed by ``ros2 topic echo`` as key-value pairs, shown by the diagnostics
viewers, found in a bag by its topic.
"""

from __future__ import annotations

import json
from typing import Any

from stillframe.contract import messages

OK, WARN = 0, 1
#: the record's fields that come first in ``values``
FIRST = ("kind", "t")


def summary(record: dict[str, Any]) -> str:
    """One line: what was decided, when."""
    kind, t = record["kind"], record["t"]
    if kind == "detection":
        return (f"change detected at t = {t:.6g} s (onset {record['onset_s']:.6g} s, mode "
                f"{record['mode'] + 1}: {record['reference_hz'][record['mode']]:.5g} -> "
                f"{record['frequency_hz'][record['mode']]:.5g} Hz)")
    if kind == "design":
        hz = ", ".join(f"{f:.5g}" for f in record["identified_hz"])
        return (f"design {record['design']} from records {record['window_s'][0]:.6g}-"
                f"{record['window_s'][1]:.6g} s ({hz} Hz), handed over at "
                f"{record['handover_s']:.6g} s")
    return f"{kind} at t = {t:.6g} s: {record.get('reason', '')}"


def event_message(stamp_ns: int, node: str, record: dict[str, Any]) -> Any:
    """The message of ``record`` decided at the sample stamped ``stamp_ns`` by ``node``."""
    kv = messages.msg_class("diagnostic_msgs/msg/KeyValue")
    keys = [*FIRST, *(k for k in record if k not in FIRST)]
    status = messages.new(
        "diagnostic_msgs/msg/DiagnosticStatus", level=OK if record["kind"] == "design" else WARN,
        name=f"{node}: adaptation {record['kind']}", message=summary(record),
        hardware_id="stillframe", values=[kv(key=k, value=json.dumps(record[k])) for k in keys])
    array = messages.new("diagnostic_msgs/msg/DiagnosticArray", status=[status])
    array.header.stamp = messages.time_msg(stamp_ns)
    return array


def read_event_message(msg: Any) -> list[dict[str, Any]]:
    """The records of one message (the inverse of :func:`event_message`)."""
    return [{kv.key: json.loads(kv.value) for kv in status.values} for status in msg.status]
