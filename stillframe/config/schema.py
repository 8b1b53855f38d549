"""Scene sections as frozen dataclasses, validated from nested YAML with errors naming the key.

A section is a ``@dataclass(frozen=True, kw_only=True)`` subclass of :class:`Section`. Each key is
a field: its annotation is its type, and :func:`key` gives its default and a :class:`Field` with
the physical check and the documentation::

    half_length: float = key(0.0825, positive, doc="L4 [m]")

The annotations understood: ``float``, ``int``, ``bool``, ``str``, ``Literal["a", "b"]`` (one of
these strings), ``tuple[float, ...]`` (a list of numbers), ``tuple[float, float, float]`` (a list
of exactly three), ``float | None`` (may be null), another section (a nested mapping) and
``tuple[Section, ...]`` (a list of mappings, each validated as that section; its entries are
named ``key[i]`` in the errors).
:func:`validate` fills defaults, converts numbers, runs each check and builds the instances;
every problem raises :class:`~stillframe.errors.InputError` naming the dotted key.
"""

from __future__ import annotations

import dataclasses
import math
import reprlib
import types
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass
from typing import Any, Literal, NamedTuple, TypeVar, get_args, get_origin, get_type_hints

from stillframe.errors import InputError

__all__ = ["SEED_RANGE", "Check", "Field", "Floats", "Floats2", "Floats3", "Floats4", "Floats8",
           "Section", "in_range", "key", "magnitude", "non_negative", "positive", "section",
           "set_dotted", "show", "up_to", "validate"]

Check = Callable[[Any], str | None]
Floats = tuple[float, ...]
Floats2 = tuple[float, float]
Floats3 = tuple[float, float, float]
Floats4 = tuple[float, float, float, float]
Floats8 = tuple[float, float, float, float, float, float, float, float]
S = TypeVar("S", bound="Section")


@dataclass(frozen=True)
class Field:
    """What a key's annotation cannot say: its physical check (an error text or None) and doc."""

    check: Check | None = None
    doc: str = ""


def key(default: Any = MISSING, check: Check | None = None, *, doc: str = "") -> Any:
    """A section field with its default (none: the key is required), check and doc."""
    return dataclasses.field(default=default, metadata={"field": Field(check, doc)})


def section(cls: type[S]) -> S:
    """A nested section field; its defaults are those of ``cls``."""
    return dataclasses.field(default_factory=cls)


@dataclass(frozen=True)
class Section:
    """Base of the scene's sections (frozen dataclasses whose fields are declared with key())."""

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dicts and lists, as YAML or JSON would hold them."""
        return {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)}


def _plain(value: Any) -> Any:
    if isinstance(value, Section):
        return value.to_dict()
    return [_plain(v) for v in value] if isinstance(value, tuple) else value


def _values(value: Any) -> tuple:
    return value if isinstance(value, tuple) else (value,)


def positive(value: Any) -> str | None:
    """The check of a key whose value (or each of its values) must be > 0; the problem, or None."""
    return None if all(v > 0 for v in _values(value)) else "must be > 0"


def non_negative(value: Any) -> str | None:
    """The check of a key whose value (or each of its values) must be >= 0; the problem, or None."""
    return None if all(v >= 0 for v in _values(value)) else "must be >= 0"


def up_to(high: float) -> Check:
    """> 0 and at most ``high``: a physical bound on a size, a rate, a count."""

    def check(value: Any) -> str | None:
        return None if all(0 < v <= high for v in _values(value)) else f"must lie in (0, {high:g}]"

    return check


def magnitude(high: float) -> Check:
    """|value| at most ``high`` (a signed quantity: an offset, an amplitude)."""
    return in_range(-high, high)


#: a random seed: what numpy's generators take (a whole number >= 0), within 64 bits
SEED_RANGE = (0, 2**63 - 1)


def in_range(low: float, high: float) -> Check:
    """A check holding a value (or each of its values) to [``low``, ``high``]."""
    def check(value: Any) -> str | None:
        ok = all(low <= v <= high for v in _values(value))
        return None if ok else f"must lie in [{low:g}, {high:g}]"

    return check


class _Spec(NamedTuple):
    """One key as its annotation and :func:`key` declare it."""

    name: str
    kind: Any  # float, int, bool, str, tuple (a list of numbers) or a Section subclass
    default: Any  # MISSING: required; nested sections: unused
    field: Field
    nullable: bool = False
    choices: tuple[str, ...] | None = None
    length: int | None = None
    entry: type[Section] | None = None  # a list of sections: the section of each entry


def _is_section(kind: Any) -> bool:
    return isinstance(kind, type) and issubclass(kind, Section)


def _spec(f: dataclasses.Field, hint: Any) -> _Spec:
    spec = _Spec(f.name, hint, f.default, f.metadata.get("field", Field()))
    args = get_args(hint)
    if get_origin(hint) is types.UnionType and type(None) in args:
        (inner,) = (a for a in args if a is not type(None))
        return _spec(f, inner)._replace(nullable=True)
    if get_origin(hint) is Literal:
        return spec._replace(kind=str, choices=args)
    if get_origin(hint) is tuple:
        if _is_section(args[0]):
            return spec._replace(kind=tuple, entry=args[0])
        length = None if args[-1] is Ellipsis else len(args)
        return spec._replace(kind=tuple, length=length)
    if hint in (float, int, bool, str) or _is_section(hint):
        return spec
    raise TypeError(f"{f.name}: a scene key cannot have the type {hint!r}")


_SPECS: dict[type, tuple[_Spec, ...]] = {}


def _specs(cls: type[Section]) -> tuple[_Spec, ...]:
    """The keys of a section class, in declaration order (worked out once per class)."""
    if cls not in _SPECS:
        hints = get_type_hints(cls)
        _SPECS[cls] = tuple(_spec(f, hints[f.name]) for f in dataclasses.fields(cls))
    return _SPECS[cls]


def _shortener(width: int) -> reprlib.Repr:
    short = reprlib.Repr()
    short.maxlevel, short.maxstring, short.maxlong, short.maxother = 3, width, width, width
    for name in ("maxtuple", "maxlist", "maxarray", "maxdict", "maxset", "maxfrozenset",
                 "maxdeque"):
        setattr(short, name, 6)
    return short


def show(value: Any, width: int = 60, *, quote: bool = True) -> str:
    """``repr(value)`` (text as it is without ``quote``) cut to ``width`` characters, for
    one-line messages. Cut while it is made (:mod:`reprlib`: the first elements, levels and
    characters), so that a value of a billion elements (a YAML alias bomb), a 3000-deep list or
    a 4000-digit number costs no more than its first ``width`` characters."""
    try:
        if quote or not isinstance(value, str):
            text = _shortener(width).repr(value)
        else:
            text = value[:width + 1]
    except (ValueError, RecursionError):     # an int beyond Python's digit limit
        text = f"<{type(value).__name__}>"
    return text if len(text) <= width else text[: width - 1] + "…"


def _number(key: str, value: Any, kind: type) -> float | int:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{key}: expected a number, got {type(value).__name__} {show(value)}")
    if kind is int:
        if isinstance(value, float) and not value.is_integer():
            raise InputError(f"{key}: expected a whole number, got {show(value)}")
        return int(value)
    try:
        value = float(value)
    except OverflowError:
        raise InputError(f"{key}: {show(value)} is too large") from None
    if not math.isfinite(value):
        raise InputError(f"{key}: must be finite, got {show(value)}")
    return value


def _entries(key: str, spec: _Spec, value: Any) -> tuple[Section, ...]:
    """A list of sections: each entry validated as ``spec.entry``, named ``key[i]``."""
    if not isinstance(value, list | tuple):
        raise InputError(f"{key}: expected a list of mappings, got {show(value)}")
    assert spec.entry is not None
    return tuple(validate(spec.entry, v, prefix=f"{key}[{i}].") for i, v in enumerate(value))


def _leaf(key: str, spec: _Spec, value: Any) -> Any:
    if value is None and spec.nullable:
        return None
    if spec.entry is not None:
        out: Any = _entries(key, spec, value)
    elif spec.kind in (float, int):
        out = _number(key, value, spec.kind)
    elif spec.kind is tuple:
        if not isinstance(value, list | tuple):
            raise InputError(f"{key}: expected a list of numbers, got {show(value)}")
        out = tuple(_number(f"{key}[{i}]", v, float) for i, v in enumerate(value))
        if spec.length is not None and len(out) != spec.length:
            raise InputError(f"{key}: expected {spec.length} values, got {len(out)}")
    elif spec.kind is bool:
        if not isinstance(value, bool):
            raise InputError(f"{key}: expected true or false, got {show(value)}")
        out = value
    else:
        if not isinstance(value, str):
            raise InputError(f"{key}: expected text, got {show(value)}")
        if spec.choices and value not in spec.choices:
            raise InputError(f"{key}: {show(value)} is not one of {', '.join(spec.choices)}")
        out = value
    problem = spec.field.check(out) if spec.field.check is not None else None
    if problem:
        raise InputError(f"{key}: {problem} (got {show(out)})")
    return out


def validate(cls: type[S], data: Any, prefix: str = "") -> S:
    """Validate ``data`` against the section ``cls``, fill defaults; InputError on the first
    problem."""
    where = prefix.rstrip(".") or "scene"
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise InputError(f"{where}: expected a mapping of keys, got {show(data)}")
    keys = _specs(cls)
    unknown = sorted(set(data) - {s.name for s in keys}, key=lambda k: show(k, quote=False))
    if unknown:
        known = ", ".join(sorted(s.name for s in keys))
        raise InputError(f"{prefix}{show(unknown[0], quote=False)}: unknown key (known here: "
                         f"{known})")
    values: dict[str, Any] = {}
    for spec in keys:
        dotted = f"{prefix}{spec.name}"
        if _is_section(spec.kind):
            values[spec.name] = validate(spec.kind, data.get(spec.name), prefix=f"{dotted}.")
        elif spec.name in data:
            values[spec.name] = _leaf(dotted, spec, data[spec.name])
        elif spec.default is MISSING:
            raise InputError(f"{dotted}: missing required field")
        else:
            values[spec.name] = spec.default
    return cls(**values)


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
