"""A small declarative schema for nested YAML documents, with errors that name the dotted key.

A schema is a dict whose values are either :class:`Field` (a leaf) or another schema dict (a
section). :func:`validate` fills defaults, converts numbers, runs each field's check and returns
nested :class:`Section` objects with attribute access. Every problem raises
:class:`~stillframe.errors.InputError` naming the key and what is wrong.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from stillframe.errors import InputError

REQUIRED = object()
Check = Callable[[Any], str | None]


@dataclass(frozen=True)
class Field:
    """A leaf value: its kind, default (or REQUIRED) and an optional physical check.

    kind is one of ``float``, ``int``, ``bool``, ``str``, ``"floats"`` (list of numbers),
    ``"any"``; ``choices`` restricts strings; ``length`` fixes a list's length; ``check`` returns
    an error text or None.
    """

    kind: Any
    default: Any = REQUIRED
    check: Check | None = None
    choices: tuple[str, ...] | None = None
    length: int | None = None
    doc: str = ""
    nullable: bool = False


@dataclass
class Section(Mapping):
    """A validated section; read values as attributes (``scene.rig.gravity``)."""

    _values: dict[str, Any] = field(default_factory=dict)

    def __getattr__(self, name: str) -> Any:
        try:
            return self.__dict__["_values"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __getitem__(self, key: str) -> Any:
        return self._values[key]

    def __iter__(self):
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def to_dict(self) -> dict[str, Any]:
        return {k: v.to_dict() if isinstance(v, Section) else v for k, v in self._values.items()}


def positive(value: Any) -> str | None:
    values = value if isinstance(value, list) else [value]
    return None if all(v > 0 for v in values) else "must be > 0"


def non_negative(value: Any) -> str | None:
    values = value if isinstance(value, list) else [value]
    return None if all(v >= 0 for v in values) else "must be >= 0"


def in_range(low: float, high: float) -> Check:
    def check(value: Any) -> str | None:
        values = value if isinstance(value, list) else [value]
        ok = all(low <= v <= high for v in values)
        return None if ok else f"must lie in [{low:g}, {high:g}]"

    return check


def _number(key: str, value: Any, kind: type) -> float | int:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{key}: expected a number, got {type(value).__name__} {value!r}")
    if kind is int:
        if isinstance(value, float) and not value.is_integer():
            raise InputError(f"{key}: expected a whole number, got {value!r}")
        return int(value)
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"{key}: must be finite, got {value!r}")
    return value


def _leaf(key: str, spec: Field, value: Any) -> Any:
    if value is None and spec.nullable:
        return None
    if spec.kind in (float, int):
        out: Any = _number(key, value, spec.kind)
    elif spec.kind == "floats":
        if not isinstance(value, list):
            raise InputError(f"{key}: expected a list of numbers, got {value!r}")
        out = [_number(f"{key}[{i}]", v, float) for i, v in enumerate(value)]
        if spec.length is not None and len(out) != spec.length:
            raise InputError(f"{key}: expected {spec.length} values, got {len(out)}")
    elif spec.kind is bool:
        if not isinstance(value, bool):
            raise InputError(f"{key}: expected true or false, got {value!r}")
        out = value
    elif spec.kind is str:
        if not isinstance(value, str):
            raise InputError(f"{key}: expected text, got {value!r}")
        if spec.choices and value not in spec.choices:
            raise InputError(f"{key}: {value!r} is not one of {', '.join(spec.choices)}")
        out = value
    else:
        out = value
    if spec.check is not None and out is not None:
        problem = spec.check(out)
        if problem:
            raise InputError(f"{key}: {problem} (got {out!r})")
    return out


def validate(schema: Mapping[str, Any], data: Any, prefix: str = "") -> Section:
    """Validate ``data`` against ``schema``, fill defaults; InputError on the first problem."""
    where = prefix.rstrip(".") or "scene"
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise InputError(f"{where}: expected a mapping of keys, got {data!r}")
    unknown = sorted(set(data) - set(schema))
    if unknown:
        known = ", ".join(sorted(schema))
        raise InputError(f"{prefix}{unknown[0]}: unknown key (known here: {known})")
    values: dict[str, Any] = {}
    for name, spec in schema.items():
        key = f"{prefix}{name}"
        if isinstance(spec, Mapping):
            values[name] = validate(spec, data.get(name), prefix=f"{key}.")
            continue
        if name not in data:
            if spec.default is REQUIRED:
                raise InputError(f"{key}: missing required field")
            values[name] = list(spec.default) if isinstance(spec.default, list) else spec.default
            continue
        values[name] = _leaf(key, spec, data[name])
    return Section(values)


def set_dotted(data: dict[str, Any], dotted: str, value: Any) -> None:
    """Set ``a.b.c = value`` in nested dicts, creating sections on the way."""
    parts = dotted.split(".")
    if not all(parts):
        raise InputError(f"--set {dotted}: empty part in the key")
    node = data
    for i, part in enumerate(parts[:-1]):
        child = node.get(part)
        if child is None:
            child = node[part] = {}
        if not isinstance(child, dict):
            where = ".".join(parts[: i + 1])
            raise InputError(f"--set {dotted}: {where} is a value, not a section")
        node = child
    node[parts[-1]] = value
