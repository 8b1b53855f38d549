"""Axis labels of scene keys, read from the schema: the ``doc`` each key declares with
:func:`~stillframe.config.schema.key` carries its symbol and unit (``"m1..m3 [kg]"``), so a plot of
``rig.floor_masses.2`` is labelled ``m2 [kg] (rig.floor_masses.2)``.

A key whose doc declares no unit is labelled ``[-]`` when it is a count or a choice (an integer,
a flag, a string) and ``[unit not declared]`` otherwise, which the plot test refuses: a number
without a unit is a defect of its declaration, to be fixed there.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any, Literal, get_origin, get_type_hints

from stillframe.config.schema import Field, Section
from stillframe.errors import InputError

UNIT = re.compile(r"\[[^\]]+\]")
#: ``m1..m3``: a symbol numbered over the elements of a list
RANGE = re.compile(r"\b([A-Za-z]+)1\.\.\1?\d\b")
NO_UNIT = "[unit not declared]"


def _field(cls: type[Section], name: str, dotted: str) -> tuple[Any, Field]:
    fields = {f.name: f for f in dataclasses.fields(cls)}
    if name not in fields:
        raise InputError(f"{dotted}: the scene has no key {name!r} in {cls.__name__}")
    return get_type_hints(cls)[name], fields[name].metadata.get("field", Field())


def key_doc(dotted: str) -> tuple[str, Any, int | None]:
    """The doc, annotation and 1-based list index (None for a scalar) of a scene key such as
    ``rig.floor_masses.2`` (as the Monte Carlo table names the list's elements)."""
    from stillframe.config.scene import Scene

    cls: Any = Scene
    parts = dotted.split(".")
    for i, part in enumerate(parts):
        kind, field = _field(cls, part, dotted)
        if isinstance(kind, type) and issubclass(kind, Section):
            cls = kind
            continue
        rest = parts[i + 1:]
        if len(rest) > 1 or (rest and not rest[0].isdigit()):
            raise InputError(f"{dotted}: {'.'.join(parts[:i + 1])} is not a section")
        return field.doc, kind, int(rest[0]) if rest else None
    raise InputError(f"{dotted}: a section, not a key")


def key_label(dotted: str) -> str:
    """``m2 [kg] (rig.floor_masses.2)``: the key's symbol or description with its unit, and the
    key itself."""
    doc, kind, index = key_doc(dotted)
    name = [p for p in dotted.split(".") if not p.isdigit()][-1]
    text = f"{name.replace('_', ' ')} {doc}" if doc.startswith("[") or not doc else doc
    if index is not None:
        text = RANGE.sub(lambda m: f"{m[1]}{index}", text) if RANGE.search(text) else (
            f"{text} #{index}" if text else f"#{index}")
    if not UNIT.search(text):
        counted = kind in (int, bool, str) or get_origin(kind) is Literal
        text = f"{text} {'[-]' if counted else NO_UNIT}".strip()
    return f"{text} ({dotted})"
