"""ROS 2 Jazzy messages from the ``rosbags`` typestore: lookup, construction, CDR, type hashes.

Every message the stack exchanges is a ``rosbags`` message instance (a dataclass of the
Jazzy typestore, ``Stores.ROS2_JAZZY``); numeric arrays and sequences are numpy arrays, as
``rosbags`` expects them. The CDR produced here is what goes on the wire and into bags.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype

from stillframe.errors import InputError
from stillframe.locations import DATA_DIR

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
#: ``.srv`` definitions of the services the stack serves (``rcl_interfaces``' parameter
#: services; ``lifecycle_msgs``' in its directory), missing from the ``rosbags`` typestore.
SERVICE_DEFINITIONS = DATA_DIR / "srv"


def register_services(package: str, directory: Path) -> None:
    """Register ``package/srv/Name_Request`` and ``_Response`` of every ``Name.srv`` in
    ``directory`` (fields of other types refer to ``package/msg/...``, as in ``.srv`` files)."""
    types = {}
    for path in sorted(directory.glob("*.srv")):
        request, response = ("\n" + path.read_text()).split("\n---\n")
        for text, part in ((request, "Request"), (response, "Response")):
            parsed = get_types_from_msg(text, f"{package}/msg/{path.stem}_{part}")
            types.update({name.replace("/msg/", "/srv/", 1): defs
                          for name, defs in parsed.items()})
    TYPESTORE.register(types)


register_services("rcl_interfaces", SERVICE_DEFINITIONS)
register_services("lifecycle_msgs", SERVICE_DEFINITIONS / "lifecycle_msgs")

#: numpy dtype of each ROS primitive that ``rosbags`` keeps in numpy arrays.
NUMPY_DTYPES: dict[str, type] = {
    "bool": np.bool_, "byte": np.uint8, "char": np.uint8,
    "int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
    "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
    "float32": np.float32, "float64": np.float64,
}


def type_name(name: str | type) -> str:
    """Canonical ``pkg/msg/Type`` of ``pkg/msg/Type``, ``pkg/Type`` or a message class;
    InputError if unknown."""
    name = getattr(name, "__msgtype__", name)
    parts = name.split("/")
    canonical = f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name
    if canonical not in TYPESTORE.fielddefs:
        raise InputError(f"unknown message type {name!r} (expected e.g. 'sensor_msgs/msg/Imu')")
    return canonical


def msg_class(name: str) -> type:
    """The ``rosbags`` dataclass of a message type."""
    return TYPESTORE.types[type_name(name)]


def fielddefs(name: str) -> list[tuple[str, tuple[Nodetype, Any]]]:
    """The ``rosbags`` field definitions ``[(field, (nodetype, detail)), ...]`` of a type."""
    return TYPESTORE.fielddefs[type_name(name)][1]


def _default(desc: tuple[Nodetype, Any]) -> Any:
    kind, detail = desc
    if kind == Nodetype.BASE:
        prim = detail[0]
        return "" if prim == "string" else NUMPY_DTYPES[prim](0).item()
    if kind == Nodetype.NAME:
        return new(detail)
    sub, size = detail
    if sub[0] == Nodetype.BASE and sub[1][0] in NUMPY_DTYPES:
        return np.zeros(size if kind == Nodetype.ARRAY else 0, dtype=NUMPY_DTYPES[sub[1][0]])
    return [_default(sub) for _ in range(size)] if kind == Nodetype.ARRAY else []


def new(name: str, /, **fields: Any) -> Any:
    """A message of type ``name`` with zero/empty defaults, overridden by ``fields``.

    Numeric sequences given as lists are converted to numpy arrays of the field's dtype. The
    typestore carries no ``.msg`` default values: ``geometry_msgs/msg/Quaternion.w`` is 0 here
    (1 in ROS), so set such fields explicitly.
    """
    cls = msg_class(name)
    defs = dict(fielddefs(name))
    unknown = set(fields) - set(defs)
    if unknown:
        raise InputError(f"{type_name(name)} has no field(s) {', '.join(sorted(unknown))}")
    values = {}
    for field, desc in defs.items():
        if field not in fields:
            values[field] = _default(desc)
            continue
        value = fields[field]
        kind, detail = desc
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and detail[0][0] == Nodetype.BASE:
            prim = detail[0][1][0]
            if prim in NUMPY_DTYPES:
                value = np.asarray(value, dtype=NUMPY_DTYPES[prim])
        values[field] = value
    return cls(**values)


def serialize(msg: Any) -> bytes:
    """Little-endian CDR (with the 4-byte encapsulation header) of a ``rosbags`` message."""
    return bytes(TYPESTORE.serialize_cdr(msg, msg.__msgtype__))


def deserialize(data: bytes | memoryview, name: str) -> Any:
    """The ``rosbags`` message decoded from CDR ``data`` of type ``name``."""
    return TYPESTORE.deserialize_cdr(data, type_name(name))


#: what decoding bytes that are not a valid CDR message of the type raises
MALFORMED_ERRORS = (SerdeError, UnicodeDecodeError, struct.error, IndexError, ValueError,
                    OverflowError)


def decode_sample(data: bytes | memoryview, name: str) -> Any | None:
    """:func:`deserialize`, or None for bytes that are not a valid message of type ``name``
    (truncated or garbage CDR from a faulty or hostile writer)."""
    try:
        return deserialize(data, name)
    except MALFORMED_ERRORS:
        return None


def prepare(name: str) -> None:
    """Generate the ``rosbags`` CDR code of a type now, so its first message is not late."""
    deserialize(serialize(new(name)), name)


def type_hash(name: str) -> str:
    """The ROS 2 type hash ``RIHS01_<sha256 hex>`` of a message type (REP 2011)."""
    return TYPESTORE.hash_rihs01(type_name(name))


def time_msg(nanoseconds: int) -> Any:
    """``builtin_interfaces/msg/Time`` for a time in integer nanoseconds."""
    sec, nanosec = divmod(int(nanoseconds), 1_000_000_000)
    return msg_class("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def stamp_ns(stamp: Any) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/msg/Time``."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def to_plain(msg: Any) -> Any:
    """Nested dicts, lists and Python scalars of a message, in field order (for printing)."""
    if hasattr(msg, "__msgtype__"):
        return {field: to_plain(getattr(msg, field)) for field, _ in fielddefs(msg.__msgtype__)}
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, list):
        return [to_plain(item) for item in msg]
    return msg
