"""``structure_events`` (:data:`~stillframe.contract.topics.STRUCTURE_EVENTS`): the changes of
the plant's structure the simulator applied, as ``diagnostic_msgs/DiagnosticArray``.

One message per sample at which events applied, stamped with the sample's time; one
``DiagnosticStatus`` per event, whose ``values`` carry the event's record
(:meth:`stillframe.loop.spec.StructureEvent.record`) as JSON text: ``event``, ``time_s``,
``applied_s`` and ``sample``, then each scene key the event changed (``rig.floor_masses``,
``damping.alpha``, …) with its value after the event. A DiagnosticArray because it is
stamped in the loop's time (a bag's log times are wall times), ``ros2 topic echo`` prints it as
key-value pairs, and the diagnostics viewers (rqt_runtime_monitor, Foxglove's diagnostics panel)
show it as it is; and an own topic rather than ``/diagnostics`` because an event is a fact of the
experiment, which a bag reader finds by topic, not a node's periodic status.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from stillframe.contract import messages

#: the record's fields that come first in ``values``, in this order (the rest: the changes)
RECORD_FIELDS = ("event", "time_s", "applied_s", "sample")
OK = 0


def summary(record: dict[str, Any]) -> str:
    """One line: which event, when, what it changed."""
    changed = "; ".join(f"{k} = {json.dumps(v)}" for k, v in record["changes"].items())
    return (f"events[{record['event']}] (at {record['time_s']:g} s) applied at "
            f"t = {record['applied_s']:g} s, sample {record['sample']}: {changed}")


def event_message(stamp_ns: int, node: str, records: Sequence[dict[str, Any]]) -> Any:
    """The message of the events ``records`` applied at the sample stamped ``stamp_ns``, by
    the node named ``node``."""
    kv = messages.msg_class("diagnostic_msgs/msg/KeyValue")
    status = [messages.new(
        "diagnostic_msgs/msg/DiagnosticStatus", level=OK,
        name=f"{node}: events[{record['event']}]", message=summary(record),
        hardware_id="stillframe",
        values=[*(kv(key=k, value=json.dumps(record[k])) for k in RECORD_FIELDS),
                *(kv(key=k, value=json.dumps(v)) for k, v in record["changes"].items())])
        for record in records]
    array = messages.new("diagnostic_msgs/msg/DiagnosticArray", status=status)
    array.header.stamp = messages.time_msg(stamp_ns)
    return array


def read_event_message(msg: Any) -> list[dict[str, Any]]:
    """The records of one message (the inverse of :func:`event_message`)."""
    records = []
    for status in msg.status:
        values = {kv.key: json.loads(kv.value) for kv in status.values}
        record = {k: values.pop(k) for k in RECORD_FIELDS}
        records.append({**record, "changes": values})
    return records
