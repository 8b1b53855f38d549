"""ROS parameters as ``rcl_interfaces`` messages, and the four parameter services' answers.

A value is a ``rcl_interfaces/msg/ParameterValue`` with its ``type`` code (``ParameterType``)
and one filled field; what ``ListParameters``, ``GetParameters``, ``SetParameters`` and
``DescribeParameters`` answer for a node's :class:`.params.Parameters` follows rclpy's
``ParameterService`` (an undeclared name gets an unset value or a refusal, never an error).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from stillframe.contract import messages
from stillframe.errors import InputError
from stillframe.middleware.params import (
    ParameterDescriptor,
    Parameters,
    Range,
    SetParametersResult,
    check_value,
)

NOT_SET, BOOL, INTEGER, DOUBLE, STRING = 0, 1, 2, 3, 4
BYTE_ARRAY, BOOL_ARRAY, INTEGER_ARRAY, DOUBLE_ARRAY, STRING_ARRAY = 5, 6, 7, 8, 9
#: (type code, ParameterValue field) per Python type of a scalar or of a list's items
FIELDS: dict[tuple[type, bool], tuple[int, str]] = {
    (bool, False): (BOOL, "bool_value"), (int, False): (INTEGER, "integer_value"),
    (float, False): (DOUBLE, "double_value"), (str, False): (STRING, "string_value"),
    (bool, True): (BOOL_ARRAY, "bool_array_value"),
    (int, True): (INTEGER_ARRAY, "integer_array_value"),
    (float, True): (DOUBLE_ARRAY, "double_array_value"),
    (str, True): (STRING_ARRAY, "string_array_value"),
}
FIELD_OF_CODE = {code: field for code, field in FIELDS.values()} | {BYTE_ARRAY: "byte_array_value"}
#: the types' names as ros2param prints them (``ros2 param describe``)
TYPE_NAMES = {NOT_SET: "not set", BOOL: "boolean", INTEGER: "integer", DOUBLE: "double",
              STRING: "string", BYTE_ARRAY: "byte array", BOOL_ARRAY: "boolean array",
              INTEGER_ARRAY: "integer array", DOUBLE_ARRAY: "double array",
              STRING_ARRAY: "string array"}
VALUE_TYPE = "rcl_interfaces/msg/ParameterValue"


def type_code(value: Any) -> int:
    """The ``ParameterType`` code of a parameter value (None: NOT_SET)."""
    if value is None:
        return NOT_SET
    value = check_value(value, "parameter value")
    item = value[0] if isinstance(value, list) else value
    return FIELDS[(type(item), isinstance(value, list))][0]


def value_msg(value: Any) -> Any:
    """The ``ParameterValue`` message of a Python value (None: NOT_SET)."""
    code = type_code(value)
    return messages.new(VALUE_TYPE, type=code, **({FIELD_OF_CODE[code]: value} if code else {}))


def value_of(msg: Any) -> Any:
    """The Python value of a ``ParameterValue`` (lists for arrays, None when NOT_SET);
    InputError for an unknown type code."""
    if msg.type == NOT_SET:
        return None
    if msg.type not in FIELD_OF_CODE:
        raise InputError(f"parameter value of unknown type {msg.type}")
    value = getattr(msg, FIELD_OF_CODE[msg.type])
    return value.tolist() if isinstance(value, np.ndarray) else value


def result_msg(result: SetParametersResult) -> Any:
    """``result`` as an ``rcl_interfaces/msg/SetParametersResult`` (successful, and the reason when
    not)."""
    return messages.new("rcl_interfaces/msg/SetParametersResult",
                        successful=result.successful, reason=result.reason)


def _listed(name: str, prefixes: list[str], depth: int) -> bool:
    """rclpy's rule: within ``depth`` dots below the root or a prefix (0: any depth)."""
    dots = name.count(".")
    if not prefixes:
        return depth == 0 or dots < depth
    return any(name == p or (name.startswith(p + ".") and (
        depth == 0 or dots - p.count(".") <= depth)) for p in prefixes)


def answer_list(params: Parameters, request: Any) -> Any:
    """The ``~/list_parameters`` response: the names within ``request.depth`` of
    ``request.prefixes`` (rclpy's rule) and the first components of the dotted ones among them."""
    names = [n for n in params.values if _listed(n, list(request.prefixes), request.depth)]
    prefixes = list(dict.fromkeys(n.split(".", 1)[0] for n in names if "." in n))
    result = messages.new("rcl_interfaces/msg/ListParametersResult", names=names,
                          prefixes=prefixes)
    return messages.new("rcl_interfaces/srv/ListParameters_Response", result=result)


def answer_get(params: Parameters, request: Any) -> Any:
    """The ``~/get_parameters`` response: one ``ParameterValue`` per requested name, NOT_SET for a
    name the node does not have."""
    return messages.new("rcl_interfaces/srv/GetParameters_Response",
                        values=[value_msg(params.values.get(n)) for n in request.names])


def answer_set(params: Parameters, request: Any) -> Any:
    """The ``~/set_parameters`` response: each parameter set in turn, each with its own result; a
    refused value (an :class:`~stillframe.errors.InputError`) gives an unsuccessful result with its
    reason and does not stop the others."""
    results = []
    for p in request.parameters:
        try:
            result = params.set(p.name, value_of(p.value))
        except InputError as exc:
            result = SetParametersResult(False, str(exc))
        results.append(result_msg(result))
    return messages.new("rcl_interfaces/srv/SetParameters_Response", results=results)


#: the bounds of an ``IntegerRange`` (int64) that stand for an infinite bound
INT64 = (-(2**63), 2**63 - 1)


def range_fields(value: Any, limits: Range | None) -> dict[str, Any]:
    """The ``floating_point_range`` or ``integer_range`` of a descriptor for a parameter of
    ``value``'s type (none for other types, as rcl gives ranges to scalars only)."""
    if limits is None or isinstance(value, bool) or not isinstance(value, int | float):
        return {}
    if isinstance(value, float):
        return {"floating_point_range": [messages.new(
            "rcl_interfaces/msg/FloatingPointRange", from_value=float(limits.low),
            to_value=float(limits.high), step=float(limits.step))]}
    low, high = (int(b) if math.isfinite(b) else INT64[b > 0] for b in (limits.low, limits.high))
    return {"integer_range": [messages.new("rcl_interfaces/msg/IntegerRange", from_value=low,
                                           to_value=high, step=int(limits.step))]}


def descriptor_msg(name: str, value: Any, descriptor: ParameterDescriptor) -> Any:
    """The ``ParameterDescriptor`` message of a declared parameter (``value``: its value now)."""
    return messages.new("rcl_interfaces/msg/ParameterDescriptor", name=name,
                        type=type_code(value), description=descriptor.description,
                        additional_constraints=descriptor.additional_constraints,
                        read_only=descriptor.read_only,
                        **range_fields(value, descriptor.range))


def answer_describe(params: Parameters, request: Any) -> Any:
    """Every name's descriptor; an undeclared one's is empty but for the name, as rclpy's."""
    return messages.new("rcl_interfaces/srv/DescribeParameters_Response", descriptors=[
        descriptor_msg(n, params.values.get(n),
                       params.descriptors.get(n, ParameterDescriptor()))
        for n in request.names
    ])


#: service name (under the node's name) -> (service type, answer)
PARAMETER_SERVICES = {
    "list_parameters": ("rcl_interfaces/srv/ListParameters", answer_list),
    "get_parameters": ("rcl_interfaces/srv/GetParameters", answer_get),
    "set_parameters": ("rcl_interfaces/srv/SetParameters", answer_set),
    "describe_parameters": ("rcl_interfaces/srv/DescribeParameters", answer_describe),
}
