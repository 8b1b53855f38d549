"""A message from YAML values, as ``ros2 topic pub TOPIC TYPE 'YAML'`` fills one
(``rosidl_runtime_py.set_message_fields``): fields left out keep their zero defaults, nested
messages are mappings, a ``builtin_interfaces/msg/Time`` field may be ``now`` and a
``std_msgs/msg/Header`` field ``auto`` (stamped with the time of each publish)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rosbags.typesys.base import Nodetype

from stillframe.contract import messages
from stillframe.errors import InputError

TIME = "builtin_interfaces/msg/Time"
HEADER = "std_msgs/msg/Header"
INTEGERS = {"byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
            "uint64"}
#: sets the time fields written ``now``/``auto`` to a stamp (called before each publish)
Stamper = Callable[[int], None]


def _scalar(prim: str, value: Any, where: str) -> Any:
    if prim == "string":
        if not isinstance(value, str):
            raise InputError(f"{where}: expected a string, got {value!r}")
        return value
    if prim == "bool":
        if not isinstance(value, bool):
            raise InputError(f"{where}: expected true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where}: expected a number ({prim}), got {value!r}")
    if prim in INTEGERS:
        if isinstance(value, float) and not value.is_integer():
            raise InputError(f"{where}: expected an integer ({prim}), got {value!r}")
        return int(value)
    return float(value)


def _value(desc: tuple[Nodetype, Any], value: Any, where: str, stampers: list[Stamper]) -> Any:
    kind, detail = desc
    if kind == Nodetype.BASE:
        return _scalar(detail[0], value, where)
    if kind == Nodetype.NAME:
        return from_yaml(detail, value, where, stampers)
    sub, size = detail
    if not isinstance(value, list):
        raise InputError(f"{where}: expected a list, got {value!r}")
    if kind == Nodetype.ARRAY and len(value) != size:
        raise InputError(f"{where}: expected {size} values, got {len(value)}")
    if kind == Nodetype.SEQUENCE and size and len(value) > size:
        raise InputError(f"{where}: at most {size} values, got {len(value)}")
    return [_value(sub, v, f"{where}[{i}]", stampers) for i, v in enumerate(value)]


def from_yaml(name: str, values: Any, where: str = "", stampers: list[Stamper] | None = None,
              ) -> Any:
    """The message of type ``name`` with ``values`` (a mapping of its fields); the time fields
    given as ``now`` (a Time) or ``auto`` (a Header) get a :data:`Stamper` in ``stampers``."""
    stampers = [] if stampers is None else stampers
    where = where or messages.type_name(name)
    canonical = messages.type_name(name)
    if values in ("now", "auto") and canonical in (TIME, HEADER):
        msg = messages.new(canonical)
        time_msg = msg if canonical == TIME else msg.stamp

        def stamp(ns: int, time_msg: Any = time_msg) -> None:
            time_msg.sec, time_msg.nanosec = divmod(ns, 1_000_000_000)

        stampers.append(stamp)
        return msg
    if values is None:
        values = {}
    if not isinstance(values, dict):
        raise InputError(f"{where}: expected a mapping of the fields of {canonical}, "
                         f"got {values!r}")
    defs = dict(messages.fielddefs(canonical))
    if unknown := sorted(set(values) - set(defs)):
        raise InputError(f"{where}: no field {unknown[0]!r} (fields of {canonical}: "
                         f"{', '.join(defs)})")
    fields = {field: _value(defs[field], value, f"{where}.{field}", stampers)
              for field, value in values.items()}
    return messages.new(canonical, **fields)
