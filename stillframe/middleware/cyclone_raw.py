"""Raw CDR in and out of Cyclone DDS: the only place that calls cyclonedds' private C layer.

The public cyclonedds Python API (de)serializes through IDL classes; ROS 2's wire format is
handled here as bytes instead (``stillframe.contract.messages`` encodes it), so writing and
taking go through ``cyclonedds._clayer`` on the entities' ``_ref`` handles. Used with
cyclonedds 11.0.1 (the version ``make setup`` installs); if its private layer changes, this
module is what to adapt.
"""

from __future__ import annotations

import ctypes
from typing import Any

from cyclonedds.core import DDSException, Entity, InstanceState, SampleState, ViewState, WaitSet
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader

from cyclonedds._clayer import (  # isort: skip
    ddspy_get_matched_publication_data,
    ddspy_take,
    ddspy_write,
    ddspy_write_ts,
)

#: every sample, read or not, of every instance
ANY_SAMPLES = SampleState.Any | ViewState.Any | InstanceState.Any


def pad4(cdr: bytes | bytearray) -> bytes | bytearray:
    """CDR padded to a multiple of 4 bytes, as Cyclone expects of a serialized sample (the same
    object, not a copy, when it is)."""
    return cdr + b"\0" * (-len(cdr) % 4) if len(cdr) % 4 else cdr


def write_raw(writer: DataWriter, cdr: bytes | bytearray, timestamp_ns: int | None = None) -> None:
    """Write one serialized sample (CDR with encapsulation header), stamped ``timestamp_ns``
    (source time) if given."""
    data = pad4(cdr)
    ret = ddspy_write(writer._ref, data) if timestamp_ns is None else ddspy_write_ts(
        writer._ref, data, timestamp_ns
    )
    if ret < 0:
        raise DDSException(ret, f"writing on {writer.topic.name}")


def take_raw(reader: DataReader, limit: int) -> list[tuple[bytes, Any]]:
    """Take up to ``limit`` samples as (serialized bytes, SampleInfo) pairs."""
    return ddspy_take(reader._ref, ANY_SAMPLES, limit)


def writer_guid(reader: DataReader, handle: int) -> bytes | None:
    """The GUID of the writer matched with ``reader`` under instance handle ``handle`` (None if
    not matched). ``get_matched_publication_data`` converts the writer's whole QoS and type
    information in Python, which each topic's first sample would pay; only the key is taken here."""
    return ddspy_get_matched_publication_data(reader._ref, handle, _key_only, _no_qos)


def _key_only(keybytes: bytes, *_rest: Any) -> bytes:
    return keybytes


def _no_qos(_pointer: Any) -> None:
    return None


def matched_count(entity: DataWriter | DataReader) -> int:
    """How many readers a writer (writers a reader) is matched with: ``dds_get_matched_*`` with
    no buffer returns the count. cyclonedds' ``get_matched_subscriptions()`` asks for the count,
    then fills a list of that size; when an endpoint matches in between (a monitor joining) the
    second call reports more than the list holds and it raises IndexError."""
    if isinstance(entity, DataWriter):
        count = entity._get_matched_subscriptions(entity._ref, None, 0)
    else:
        count = entity._get_matched_publications(entity._ref, None, 0)
    if count < 0:
        raise DDSException(count, f"Occurred when counting the matched endpoints of {entity!r}")
    return int(count)


def attach(waitset: WaitSet, entity: Entity) -> int:
    """Attach ``entity`` to ``waitset``; the key :func:`wait_triggered` reports it by."""
    waitset.attach(entity)
    return attach_key(waitset, entity)


def attach_key(waitset: WaitSet, entity: Entity) -> int:
    """The key of an attached ``entity``: cyclonedds attaches each entity with the address of a
    ``c_int`` it keeps beside it as the attach value."""
    return next(ctypes.addressof(value) for attached, value in waitset.attached
                if attached is entity)


def wait_triggered(waitset: WaitSet, timeout_ns: int, keys: ctypes.Array) -> int:
    """Wait up to ``timeout_ns`` (0: do not wait) for an attached entity to trigger; the number
    of triggered ones, whose keys (:func:`attach`) are then the first entries of ``keys`` (at
    most ``len(keys)``; the others stay triggered for the next wait)."""
    ret = waitset._waitset_wait(waitset._ref, keys, len(keys), timeout_ns)
    if ret < 0:
        raise DDSException(ret, f"Occurred while waiting in {waitset!r}")
    return min(int(ret), len(keys))


def key_slots(count: int) -> ctypes.Array:
    """Room for the keys of ``count`` triggered entities (:func:`wait_triggered`)."""
    return (ctypes.c_void_p * max(count, 1))()
