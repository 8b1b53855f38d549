"""ROS 2 command-line arguments and parameter files, as ``ros2 run`` passes them to a node.

Understood after ``--ros-args`` (until ``--``): ``-p/--param name:=value`` (the value parsed
as YAML like rcl, ``1e-4`` being a number), ``--params-file FILE``,
``-r/--remap [node:]from:=to`` (``__ns``, ``__node`` and topic remaps), ``--log-level LEVEL``.
Parameter files have the rcl layout ``<node key>: {ros__parameters: {...}}``, nested keys
joined with ``.``; a node key is the fully qualified node name (a missing leading ``/`` is
added, as in rcl) and may use the wildcards ``*`` (one token) and ``**`` (any tokens), e.g.
``/**:`` or ``/frame/sim_node:``.
Overrides apply in command-line order, later ones win.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml

from stillframe.config.yamlio import MAX_YAML_BYTES, load_yaml, problem
from stillframe.errors import InputError
from stillframe.files import read_bytes

#: Types a ROS parameter may hold (arrays are homogeneous lists of the scalar types).
SCALAR_TYPES = (bool, int, float, str)


@dataclass
class RosArgs:
    """What ``--ros-args`` said, before it is matched against a particular node."""

    #: ("file", Path) or ("param", (name, value)), in command-line order
    overrides: list[tuple[str, Any]] = field(default_factory=list)
    remaps: list[tuple[str | None, str, str]] = field(default_factory=list)  # (node, from, to)
    log_level: str | None = None
    user_args: list[str] = field(default_factory=list)


def _split_assignment(text: str, flag: str) -> tuple[str, str]:
    if ":=" not in text:
        raise InputError(f"{flag} {text!r}: expected NAME:=VALUE")
    name, value = text.split(":=", 1)
    if not name:
        raise InputError(f"{flag} {text!r}: empty name")
    return name, value


def parse_value(text: str, where: str) -> Any:
    """A parameter value from its command-line text (YAML, like rcl)."""
    try:
        value = load_yaml(text) if text != "" else ""
    except yaml.YAMLError as exc:
        raise InputError(f"{where}: cannot parse value {text!r}: {exc.__class__.__name__}") from exc
    return check_value(value, where)


def check_value(value: Any, where: str) -> Any:
    """``value`` if ROS parameters can hold it (scalar or homogeneous list), else InputError."""
    if isinstance(value, SCALAR_TYPES):
        return value
    if isinstance(value, list) and value:
        kinds = {bool if isinstance(v, bool) else type(v) for v in value}
        if len(kinds) == 1 and kinds <= set(SCALAR_TYPES):
            return value
        if kinds == {int, float}:
            return [float(v) for v in value]
    raise InputError(f"{where}: {value!r} is not a ROS parameter value (scalar or uniform list)")


def parse_ros_args(argv: list[str]) -> RosArgs:
    """Split ``argv`` (without the program name) into ROS arguments and the user's own."""
    result = RosArgs()
    i, in_ros = 0, False
    while i < len(argv):
        arg = argv[i]
        if arg == "--ros-args":
            in_ros = True
        elif in_ros and arg == "--":
            in_ros = False
        elif not in_ros:
            result.user_args.append(arg)
        else:
            if arg not in ("-p", "--param", "--params-file", "-r", "--remap", "--log-level"):
                raise InputError(f"unknown ROS argument {arg!r} after --ros-args")
            if i + 1 >= len(argv):
                raise InputError(f"ROS argument {arg} needs a value")
            value = argv[i + 1]
            i += 1
            if arg in ("-p", "--param"):
                name, text = _split_assignment(value, arg)
                result.overrides.append(("param", (name, parse_value(text, f"{arg} {name}"))))
            elif arg == "--params-file":
                result.overrides.append(("file", Path(value)))
            elif arg == "--log-level":
                result.log_level = value.rsplit(":=", 1)[-1].lower()
            else:
                source, target = _split_assignment(value, arg)
                node, _, source = source.rpartition(":") if ":" in source else (None, "", source)
                result.remaps.append((node or None, source, target))
        i += 1
    return result


def _flatten(prefix: str, tree: Any, where: str) -> dict[str, Any]:
    if isinstance(tree, dict):
        flat: dict[str, Any] = {}
        for key, sub in tree.items():
            flat.update(_flatten(f"{prefix}.{key}" if prefix else str(key), sub, where))
        return flat
    return {prefix: check_value(tree, f"{where}: parameter {prefix!r}")}


#: the node key of parameters for every node, and of ``-p`` on the command line
WILDCARD = "/**"


def key_matches(key: str, node_fqn: str) -> bool:
    key = key if key.startswith("/") else "/" + key
    pattern = "".join(
        "(/[^/]+)*" if token == "**" else "/[^/]+" if token == "*" else "/" + re.escape(token)
        for token in key.strip("/").split("/")
    )
    return re.fullmatch(pattern, node_fqn) is not None


def param_file_entries(path: Path) -> list[tuple[str, dict[str, Any]]]:
    """(node key, flattened parameters) of each entry of a ROS 2 parameter file, in file order."""
    raw = read_bytes(path, what="parameter file", max_bytes=MAX_YAML_BYTES)
    try:
        tree = load_yaml(raw)
    except yaml.YAMLError as exc:
        raise InputError(f"parameter file {path}: not valid YAML: {problem(exc)}") from None
    if not isinstance(tree, dict):
        raise InputError(f"parameter file {path}: expected 'node_name: {{ros__parameters: ...}}'")
    entries = []
    for key, body in tree.items():
        if not isinstance(body, dict) or not isinstance(body.get("ros__parameters"), dict):
            raise InputError(f"parameter file {path}: node {key!r} has no 'ros__parameters' map")
        entries.append((str(key), _flatten("", body["ros__parameters"], f"parameter file {path}")))
    return entries


def resolve_entries(entries: list[tuple[str, dict[str, Any]]], node_fqn: str) -> dict[str, Any]:
    """What rcl and rclpy make of ``entries`` for ``node_fqn``: entries under the same key merge
    in order (later wins), then the ``/**`` key applies first and every other matching key after
    it, so a key naming the node wins over ``/**`` (where ``-p`` goes) whatever the order."""
    by_key: dict[str, dict[str, Any]] = {WILDCARD: {}}
    for key, params in entries:
        by_key.setdefault(key, {}).update(params)
    merged: dict[str, Any] = {}
    for key, params in by_key.items():
        if key_matches(key, node_fqn):
            merged.update(params)
    return merged


def load_param_file(path: Path, node_fqn: str) -> dict[str, Any]:
    """The parameters a ROS 2 parameter file gives the node ``node_fqn`` (flattened names)."""
    return resolve_entries(param_file_entries(path), node_fqn)


def node_overrides(ros_args: RosArgs, node_fqn: str) -> dict[str, Any]:
    """All parameter overrides for node ``node_fqn``: ``--params-file`` entries and ``-p``
    (which rcl files under ``/**``), resolved as rclpy resolves them (:func:`resolve_entries`)."""
    entries: list[tuple[str, dict[str, Any]]] = []
    for kind, value in ros_args.overrides:
        if kind == "file":
            entries += param_file_entries(value)
        else:
            entries.append((WILDCARD, {value[0]: value[1]}))
    return resolve_entries(entries, node_fqn)


def _kind(value: Any) -> str:
    if isinstance(value, list):
        return f"{_kind(value[0])}[]"
    return type(value).__name__


@dataclass(frozen=True)
class Parameter:
    """A declared parameter (``.name``, ``.value`` as in rclpy)."""

    name: str
    value: Any


#: the relative tolerance of a range's edges (rclpy's ``Node.PARAM_REL_TOL``)
PARAM_REL_TOL = 1e-6


@dataclass(frozen=True)
class Range:
    """A numeric parameter's closed range [``low``, ``high``], as ``rcl_interfaces``'
    ``FloatingPointRange`` / ``IntegerRange`` give it (``step`` 0: any value between; an
    infinite bound: none on that side, an integer range then stops at the int64 limits)."""

    low: float
    high: float
    step: float = 0

    def holds(self, value: float) -> bool:
        """Whether ``value`` lies in the range, its edges within rclpy's relative tolerance."""
        edge = any(math.isclose(value, b, rel_tol=PARAM_REL_TOL) for b in (self.low, self.high))
        return edge or self.low < value < self.high


@dataclass(frozen=True)
class ParameterDescriptor:
    """What ``rcl_interfaces/msg/ParameterDescriptor`` tells of a parameter besides its name and
    type: its description, a range (scalar integers and doubles), the constraints a range cannot
    say (choices, an open bound, a list's length), and whether it is read-only."""

    description: str = ""
    additional_constraints: str = ""
    read_only: bool = False
    range: Range | None = None


def described(descriptor: ParameterDescriptor | None, *,
              read_only: bool = False) -> ParameterDescriptor:
    """``descriptor`` (an empty one if None), read-only also when ``read_only``: what a node's
    ``declare_parameter(name, default, read_only, descriptor=...)`` declares."""
    descriptor = descriptor or ParameterDescriptor()
    return replace(descriptor, read_only=True) if read_only else descriptor


@dataclass(frozen=True)
class SetParametersResult:
    """The answer to setting parameters (rcl_interfaces/msg/SetParametersResult)."""

    successful: bool
    reason: str = ""


#: An on-set-parameters callback: the parameters about to be set; refusing refuses them all
#: (rclpy's ``add_on_set_parameters_callback``).
SetCallback = Callable[[list[Parameter]], SetParametersResult]


def _ros_kind(value: Any) -> str:
    """The ROS name of a value's parameter type (``double``, ``string[]``, ...)."""
    kind = _kind(value)
    scalar = kind.removesuffix("[]")
    return {"float": "double", "int": "integer", "str": "string"}.get(scalar, scalar) + kind[
        len(scalar):]


class Parameters:
    """A node's declared parameters: a default per name, overridden from the command line,
    set at run time through :meth:`set` (checked like rclpy: declared, not read-only, same
    type, then every on-set callback)."""

    def __init__(self, node_fqn: str, overrides: dict[str, Any]) -> None:
        self.node_fqn = node_fqn
        self.overrides = overrides
        self.values: dict[str, Any] = {}
        self.descriptors: dict[str, ParameterDescriptor] = {}
        self.callbacks: list[SetCallback] = []

    def declare(self, name: str, default: Any,
                descriptor: ParameterDescriptor = ParameterDescriptor()) -> Any:
        """Declare ``name`` with ``descriptor``: the override if one was given (same type),
        else ``default``. The start value is not held to the descriptor's range (the caller
        checks it, as :func:`stillframe.node_runtime.parameters.declare` does, in its own
        words); every later :meth:`set` is."""
        where = f"parameter {name!r} of node {self.node_fqn}"
        if name in self.values:
            raise InputError(f"{where} is already declared")
        if default is not None:
            default = check_value(default, where)
        value = self.overrides.get(name, default)
        if default is not None and value is not default:
            value = _coerce(value, default, where)
        self.values[name] = value
        self.descriptors[name] = descriptor
        return value

    @property
    def read_only(self) -> set[str]:
        """The names declared read-only."""
        return {n for n, d in self.descriptors.items() if d.read_only}

    def get(self, name: str) -> Any:
        if name not in self.values:
            raise InputError(f"parameter {name!r} of node {self.node_fqn} is not declared")
        return self.values[name]

    def set(self, name: str, value: Any) -> SetParametersResult:
        """Set one declared parameter at run time, or refuse with the reason (value kept)."""
        refusal = self._refusal(name, value)
        if refusal:
            return SetParametersResult(False, refusal)
        for callback in self.callbacks:
            result = callback([Parameter(name, value)])
            if not result.successful:
                return result
        self.values[name] = value
        return SetParametersResult(True)

    def _refusal(self, name: str, value: Any) -> str:
        if name not in self.values:
            return f"parameter {name!r} is not declared"
        descriptor = self.descriptors[name]
        if descriptor.read_only:
            return f"parameter {name!r} is read-only"
        try:
            check_value(value, name)
        except InputError as exc:
            return str(exc)
        if _kind(value) != _kind(self.values[name]):
            return (f"wrong parameter type for {name!r}: expected "
                    f"{_ros_kind(self.values[name])}, got {_ros_kind(value)}")
        limits = descriptor.range
        if limits is not None and isinstance(value, int | float) and not limits.holds(value):
            return (f"parameter {name!r} out of range [{limits.low:g}, {limits.high:g}]: "
                    f"{value!r}")
        return ""


def finite_floats(value: Any, name: str, length: int | None = None) -> str:
    """Why ``value`` is not a finite float (or, with ``length``, a list of that many finite
    floats); '' if it is. For on-set-parameters callbacks."""
    items = value if length is not None else [value]
    if length is not None and (not isinstance(value, list) or len(value) != length):
        return f"{name}: expected {length} values, got {value!r}"
    if not all(isinstance(v, float) and math.isfinite(v) for v in items):
        return f"{name}: expected finite numbers, got {value!r}"
    return ""


def _coerce(value: Any, default: Any, where: str) -> Any:
    """``value`` as the type of ``default`` (int widens to float), else InputError."""
    if _kind(value) == _kind(default):
        return value
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if _kind(default) == "float[]" and _kind(value) == "int[]":
        return [float(v) for v in value]
    raise InputError(f"{where}: expected {_kind(default)}, got {value!r} ({_kind(value)})")
