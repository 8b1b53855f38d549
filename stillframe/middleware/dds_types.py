"""ROS 2 <-> DDS naming (rmw_cyclonedds conventions) and DDS types generated from the typestore.

Topic ``/ns/name`` is DDS topic ``rt/ns/name``; message type ``pkg/msg/Type`` is DDS type
``pkg::msg::dds_::Type_``, a final keyless struct (XCDR1) whose members are the ``rosbags``
field definitions mapped onto ``cyclonedds.idl`` types (ROS ``char`` is IDL ``uint8``,
``byte`` is ``octet``, ``string<N>`` a bounded string).
"""

from __future__ import annotations

from functools import cache
from typing import Any

from cyclonedds.idl import IdlStruct, make_idl_struct
from cyclonedds.idl import types as idl
from rosbags.typesys.base import Nodetype

from stillframe.contract import messages
from stillframe.errors import InputError

TOPIC_PREFIX = "rt"

_PRIMITIVES: dict[str, Any] = {
    "bool": bool, "byte": idl.byte, "char": idl.uint8,
    "int8": idl.int8, "uint8": idl.uint8, "int16": idl.int16, "uint16": idl.uint16,
    "int32": idl.int32, "uint32": idl.uint32, "int64": idl.int64, "uint64": idl.uint64,
    "float32": idl.float32, "float64": idl.float64, "string": str,
}


def dds_topic(ros_topic: str) -> str:
    """``/a/b`` -> ``rt/a/b``."""
    return TOPIC_PREFIX + ros_topic


def ros_topic(dds_topic_name: str) -> str | None:
    """``rt/a/b`` -> ``/a/b``; None for DDS topics that are not ROS topics."""
    prefix = TOPIC_PREFIX + "/"
    return dds_topic_name[len(TOPIC_PREFIX):] if dds_topic_name.startswith(prefix) else None


def ros_service(dds_topic_name: str) -> str | None:
    """``rq/a/bRequest`` -> ``/a/b`` (the request topic names the service); None otherwise."""
    prefix, suffix = "rq/", "Request"
    if not (dds_topic_name.startswith(prefix) and dds_topic_name.endswith(suffix)):
        return None
    return dds_topic_name[len(prefix) - 1:-len(suffix)]


def dds_type(ros_type: str) -> str:
    """``pkg/msg/Type`` -> ``pkg::msg::dds_::Type_``."""
    pkg, sub, name = messages.type_name(ros_type).split("/")
    return f"{pkg}::{sub}::dds_::{name}_"


def ros_type(dds_type_name: str) -> str | None:
    """``pkg::msg::dds_::Type_`` -> ``pkg/msg/Type``; None if not a ROS type name."""
    parts = dds_type_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        return None
    name = parts[3][:-1]
    if parts[1] == "srv":  # a request or reply type names its service type
        name = name.removesuffix("_Request").removesuffix("_Response")
    return f"{parts[0]}/{parts[1]}/{name}"


def _member(desc: tuple[Nodetype, Any]) -> Any:
    kind, detail = desc
    if kind == Nodetype.BASE:
        prim, bound = detail
        if prim not in _PRIMITIVES:
            raise InputError(f"ROS primitive {prim!r} is not supported by the dds backend")
        return idl.bounded_str[bound] if prim == "string" and bound else _PRIMITIVES[prim]
    if kind == Nodetype.NAME:
        return idl_struct(detail)
    sub, size = detail
    if kind == Nodetype.ARRAY:
        return idl.array[_member(sub), size]
    return idl.sequence[_member(sub), size] if size else idl.sequence[_member(sub)]


#: rmw_cyclonedds_cpp's ``cdds_request_header_t``, before the fields of every request and
#: reply: the client's id and the request's sequence number.
REQUEST_HEADER = {"request_header_guid": idl.uint64, "request_header_seq": idl.int64}


@cache
def idl_struct(ros_type_name: str, request_header: bool = False) -> type[IdlStruct]:
    """The ``cyclonedds`` struct (final, keyless) of a ROS message type, from its fielddefs;
    with ``request_header`` (service requests and replies) the header members come first."""
    name = messages.type_name(ros_type_name)
    members = dict(REQUEST_HEADER) if request_header else {}
    members.update({field: _member(desc) for field, desc in messages.fielddefs(name)})
    return make_idl_struct(name.rsplit("/", 1)[1] + "_", dds_type(name), members)
