"""The loop nodes' parameters, declared once as data, the way a scene's keys are
(:mod:`stillframe.config.schema`).

A node's parameters are a frozen dataclass; each field is one parameter, its annotation the ROS
parameter type (``str``, ``bool``, ``int``, ``float``, ``Literal["a", "b"]`` for a choice,
``list[str]``, ``list[float]``, ``list[int]``) and :func:`param` its default, check, unit, doc and
whether it may change while the node runs::

    lockstep_timeout_s: float = param(1.0, positive, unit="s", doc="...")

:func:`declare` declares every field on a node and validates the values it got (from the command
line, a parameter file or the default) with the field's type and check; the node's
on-set-parameters callback (:func:`set_check`) refuses a read-only parameter and checks a new value
of a dynamic one with the same declaration, so ``stillframe param set`` and ``ros2 param set`` are
held to what the node was started with. A default that depends on the scene is a
:class:`FromScene`. The parameter reference in docs/nodes.md is :func:`reference` of the
declarations (``tests/unit/node_runtime/test_parameters.py`` holds the two equal).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from dataclasses import MISSING, dataclass
from typing import Any, Literal, NamedTuple, TypeVar, get_args, get_origin, get_type_hints

from stillframe.config.schema import Check
from stillframe.errors import InputError
from stillframe.middleware.params import (
    Parameter,
    ParameterDescriptor,
    Range,
    SetParametersResult,
)

__all__ = ["Bounds", "FromScene", "NodeParameters", "ParamField", "ParamSpec", "at_least",
           "between", "current", "declare", "defaults", "limited", "of_length", "param",
           "reference", "set_check"]

P = TypeVar("P", bound="NodeParameters")


@dataclass(frozen=True)
class FromScene:
    """A default taken from the scene: ``value(scene)``, documented as ``doc``."""

    doc: str
    value: Callable[[Any], Any]


@dataclass(frozen=True)
class Bounds:
    """The interval a numeric check holds a value to: ``low`` .. ``high``, either side open (the
    value itself refused) or infinite (no bound). A descriptor's range is its closure; an open
    side is said in words (:meth:`ParamSpec.descriptor`)."""

    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False

    def open_sides(self) -> list[tuple[str, float]]:
        """The finite open bounds: (``> 0`` or ``< 1``, the bound)."""
        return [(f"{sign} {bound:g}", bound) for is_open, bound, sign in (
            (self.low_open, self.low, ">"), (self.high_open, self.high, "<"))
            if is_open and math.isfinite(bound)]


@dataclass(frozen=True)
class ParamField:
    """What a parameter's annotation cannot say."""

    check: Check | None = None
    doc: str = ""
    unit: str = ""
    dynamic: bool = False
    #: the range or choices as the reference shows them (a check's own text otherwise)
    limits: str = ""

    @property
    def bounds(self) -> Bounds | None:
        """The interval the check holds each value to (None: the check is no interval)."""
        return getattr(self.check, "bounds", None)


def param(default: Any, check: Check | None = None, *, doc: str, unit: str = "",
          dynamic: bool = False, limits: str = "") -> Any:
    """A node parameter: its default (a ROS value or :class:`FromScene`), check (an error text
    or None, as the scene's checks), unit, doc; ``dynamic``: settable while the node runs. A
    list default is held as a tuple (a dataclass default must not be mutable)."""
    if isinstance(default, list):
        default = tuple(default)
    return dataclasses.field(default=default, metadata={"param": ParamField(
        check, doc, unit, dynamic, limits or getattr(check, "limits", ""))})


def limited(check: Check, limits: str, bounds: Bounds | None = None) -> Check:
    """``check`` with the text the reference shows for it (``> 0``, ``[0, 1)``...) and, when
    it holds each value to an interval, that interval (a descriptor's range)."""
    check.limits = limits  # type: ignore[attr-defined]
    check.bounds = bounds  # type: ignore[attr-defined]
    return check


def at_least(low: float, *, open_: bool = False) -> Check:
    """``value >= low`` (``> low`` with ``open_``), for each value of a list."""
    sign = ">" if open_ else ">="

    def check(value: Any) -> str | None:
        ok = all(v > low if open_ else v >= low for v in _items(value))
        return None if ok else f"must be {sign} {low:g}"

    return limited(check, f"{sign} {low:g}", Bounds(low, low_open=open_))


def between(low: float, high: float, *, high_open: bool = False) -> Check:
    """``low <= value <= high`` (``< high`` with ``high_open``)."""
    text = f"[{low:g}, {high:g}{')' if high_open else ']'}"

    def check(value: Any) -> str | None:
        ok = all(low <= v and (v < high if high_open else v <= high) for v in _items(value))
        return None if ok else f"must lie in {text}"

    return limited(check, text, Bounds(low, high, high_open=high_open))


def of_length(n: int, check: Check) -> Check:
    """A list of ``n`` values, each passing ``check``."""
    def checked(value: Any) -> str | None:
        return f"expected {n} values" if len(value) != n else check(value)

    return limited(checked, f"{n} values {getattr(check, 'limits', '')}".strip(),
                   getattr(check, "bounds", None))


positive = at_least(0, open_=True)
non_negative = at_least(0)


def _items(value: Any) -> list[Any]:
    return value if isinstance(value, list) else [value]


class ParamSpec(NamedTuple):
    """One declared parameter."""

    name: str
    kind: type            # bool, int, float, str, or list
    item: type | None     # the item type of a list
    choices: tuple[str, ...] | None
    default: Any
    field: ParamField

    @property
    def type_text(self) -> str:
        """The ROS parameter type (``double``, ``string[]``...)."""
        ros = {bool: "bool", int: "integer", float: "double", str: "string"}
        return f"{ros[self.item]}[]" if self.kind is list else ros[self.kind]

    def default_for(self, scene: Any) -> Any:
        """The ROS default (a list for a list parameter)."""
        value = self.default.value(scene) if isinstance(self.default, FromScene) else self.default
        return list(value) if isinstance(value, tuple) else value

    def descriptor(self) -> ParameterDescriptor:
        """The parameter as rclpy describes its own (``ros2 param describe``): the doc with its
        unit and a scene default's origin; the range of a scalar number (closed, step 0: any
        value); in ``additional_constraints`` what a range cannot say: the choices, an open
        bound, a list's length and items, a check that is no interval; read-only unless set at
        run time."""
        doc = self.field.doc + (f"; unit: {self.field.unit}" if self.field.unit else "")
        if isinstance(self.default, FromScene):
            doc += f"; default from the scene: {self.default.doc}"
        bounds = self.field.bounds
        scalar = self.kind in (int, float)
        if self.choices:
            constraints = "one of " + ", ".join(self.choices)
        elif bounds is not None and scalar:
            constraints = "; ".join(f"{side} ({bound:g} itself is refused; a range is closed)"
                                    for side, bound in bounds.open_sides())
        else:
            constraints = self.field.limits + (
                " (no range: a range holds a single number)" if bounds is not None else "")
        if self.kind is float or self.item is float:
            constraints = "; ".join(c for c in (constraints, "finite") if c)
        return ParameterDescriptor(
            description=_plain(doc), additional_constraints=_plain(constraints),
            read_only=not self.field.dynamic,
            range=Range(bounds.low, bounds.high) if bounds is not None and scalar else None)

    def problem(self, value: Any) -> str | None:
        """Why ``value`` is not a valid value of this parameter (None: it is)."""
        if self.kind is list:
            if not isinstance(value, list) or not all(_is(v, self.item) for v in value):
                return f"expected a list of {self.type_text[:-2]}, got {value!r}"
            items = value
        else:
            if not _is(value, self.kind):
                return f"expected {self.type_text}, got {value!r}"
            items = [value]
        if (self.kind is float or self.item is float) and not all(map(math.isfinite, items)):
            return f"must be finite, got {value!r}"
        if self.choices and value not in self.choices:
            return f"expected one of {', '.join(self.choices)}, got {value!r}"
        problem = self.field.check(value) if self.field.check else None
        if problem and ", got " not in problem:
            problem += f" (got {value!r})"
        return problem


def _plain(text: str) -> str:
    """Markdown's code marks taken out, for a descriptor's text (ros2 param describe prints it
    as it is)."""
    return text.replace("`", "")


def _is(value: Any, kind: type) -> bool:
    if kind is float:
        return isinstance(value, float)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, kind)


@dataclass(frozen=True)
class NodeParameters:
    """Base of a node's parameter declarations (frozen dataclasses of :func:`param` fields)."""

    @classmethod
    def specs(cls) -> tuple[ParamSpec, ...]:
        """The parameters in declaration order (worked out once per class)."""
        if "_specs" not in cls.__dict__:
            hints = get_type_hints(cls)
            cls._specs = tuple(_spec(f, hints[f.name]) for f in dataclasses.fields(cls))
        return cls.__dict__["_specs"]

    @classmethod
    def dynamic(cls) -> frozenset[str]:
        """The names of the parameters that may change while the node runs (declared
        ``dynamic=True``); ``ros2 param set`` refuses the others."""
        return frozenset(s.name for s in cls.specs() if s.field.dynamic)


def _spec(f: dataclasses.Field, hint: Any) -> ParamSpec:
    meta = f.metadata.get("param")
    if meta is None or f.default is MISSING:
        raise TypeError(f"{f.name}: declare node parameters with param(default, ...)")
    if get_origin(hint) is Literal:
        return ParamSpec(f.name, str, None, get_args(hint), f.default, meta)
    if get_origin(hint) is list:
        return ParamSpec(f.name, list, get_args(hint)[0], None, f.default, meta)
    if hint in (bool, int, float, str):
        return ParamSpec(f.name, hint, None, None, f.default, meta)
    raise TypeError(f"{f.name}: a node parameter cannot have the type {hint!r}")


def declare(node: Any, cls: type[P], scene: Any = None) -> P:
    """Declare every parameter of ``cls`` on ``node`` (described by its declaration,
    :meth:`ParamSpec.descriptor`: read-only unless dynamic) and return their values, each
    checked by its declaration (InputError naming the first wrong one). ``scene``
    gives the defaults taken from it."""
    values = {}
    for spec in cls.specs():
        value = node.declare_parameter(spec.name, spec.default_for(scene),
                                       descriptor=spec.descriptor()).value
        if spec.kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if problem := spec.problem(value):
            raise InputError(f"parameter {spec.name!r}: {problem}")
        values[spec.name] = value
    return cls(**values)


def defaults(cls: type[P], scene: Any = None) -> P:
    """The defaults of ``cls``'s parameters (those from the scene for ``scene``)."""
    return cls(**{s.name: s.default_for(scene) for s in cls.specs()})


def current(node: Any, cls: type[P]) -> P:
    """The values of ``cls``'s parameters as ``node`` holds them now (after sets)."""
    return cls(**{s.name: node.get_parameter(s.name).value for s in cls.specs()})


def set_check(*classes: type[NodeParameters]) -> Callable[[list[Parameter]], SetParametersResult]:
    """An on-set-parameters check by the declarations of ``classes``: a parameter not declared
    there as dynamic is refused (``use_sim_time`` and the read-only ones), a dynamic one whose
    value its declaration refuses too, with the reason."""
    specs = {s.name: s for cls in classes for s in cls.specs()}

    def check(parameters: list[Parameter]) -> SetParametersResult:
        for p in parameters:
            spec = specs.get(p.name)
            if spec is None or not spec.field.dynamic:
                return SetParametersResult(False, f"parameter {p.name!r} cannot change while "
                                                  "the node runs")
            if problem := spec.problem(p.value):
                return SetParametersResult(False, f"{p.name}: {problem}")
        return SetParametersResult(True)

    return check


def reference(nodes: dict[str, tuple[type[NodeParameters], ...]]) -> str:
    """The parameter reference (Markdown): one table of every declared parameter, with the
    nodes that declare it (one row per name and meaning)."""
    rows: dict[tuple[str, str], tuple[ParamSpec, list[str]]] = {}
    for node, classes in nodes.items():
        for cls in classes:
            for spec in cls.specs():
                rows.setdefault((spec.name, spec.field.doc), (spec, []))[1].append(node)
    lines = ["| parameter | nodes | type | default | range or choices | unit | set at run time "
             "| what it is |", "|---|---|---|---|---|---|---|---|"]
    for (name, _), (spec, where) in rows.items():
        default = (spec.default.doc if isinstance(spec.default, FromScene)
                   else _shown(spec.default))
        limits = " \\| ".join(f"`{c}`" for c in spec.choices) if spec.choices else (
            spec.field.limits)
        nodes_text = "all" if len(where) == len(nodes) else ", ".join(where)
        lines.append(f"| `{name}` | {nodes_text} | {spec.type_text} | {default} | {limits} | "
                     f"{spec.field.unit} | {'yes' if spec.field.dynamic else ''} | "
                     f"{spec.field.doc} |")
    return "\n".join(lines) + "\n"


def _shown(value: Any) -> str:
    return f"`{json.dumps(list(value) if isinstance(value, tuple) else value)}`"
