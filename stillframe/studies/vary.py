"""``--vary KEY=DIST``: how one scene key varies from run to run (docs/montecarlo.md).

DIST is one of
- ``±10%`` or ``uniform:±10%``: nominal × (1 + U(−0.1, 0.1));
- ``normal:5%``: nominal × (1 + N(0, 0.05²));
- ``a,b,c``: one of the listed values (YAML each, so ``lumped,fe`` works too);
- ``grid:lo:hi:n``: one of ``n`` evenly spaced values from ``lo`` to ``hi``.

Relative spreads need a numeric nominal (the scene's value after ``--set``); on a list-valued key
such as ``rig.floor_masses`` each element is perturbed independently. Lists and grids are
discrete: the study runs through their Cartesian product, run i taking combination
``i mod (number of combinations)``. Values reach the scene as ``--set KEY=VALUE`` overrides, so
they are validated like any other.
"""

from __future__ import annotations

import itertools
import json
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
import yaml

from stillframe.config.yamlio import load_yaml
from stillframe.errors import InputError

__all__ = ["Variation", "as_overrides", "check_nominal", "combinations", "draw", "lookup",
           "parse_vary", "perturb"]

RELATIVE = ("uniform", "normal")


@dataclass(frozen=True)
class Variation:
    """One ``--vary``: a relative spread (``uniform``, ``normal``) or discrete ``values``."""

    key: str
    kind: str
    spread: float = 0.0
    values: tuple[Any, ...] = ()

    @property
    def discrete(self) -> bool:
        return self.kind not in RELATIVE


def _percent(text: str, item: str) -> float:
    body = text.strip().removeprefix("±").removeprefix("+-").strip()
    if not body.endswith("%"):
        raise InputError(f"--vary {item}: a relative spread ends in % (e.g. ±10%)")
    try:
        value = float(body[:-1]) / 100.0
    except ValueError:
        raise InputError(f"--vary {item}: {text!r} is not a percentage") from None
    if not math.isfinite(value) or value < 0:
        raise InputError(f"--vary {item}: the spread must be a finite percentage >= 0")
    return value


def _number(text: str, item: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"--vary {item}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"--vary {item}: {text!r} is not finite")
    return value


def _grid(body: str, item: str) -> tuple[float, ...]:
    parts = body.split(":")
    if len(parts) != 3:
        raise InputError(f"--vary {item}: a grid is grid:lo:hi:n")
    lo, hi = _number(parts[0], item), _number(parts[1], item)
    try:
        n = int(parts[2])
    except ValueError:
        raise InputError(f"--vary {item}: the grid's n must be a whole number") from None
    if n < 1:
        raise InputError(f"--vary {item}: the grid needs n >= 1 points")
    return tuple(float(v) for v in np.linspace(lo, hi, n))


def _listed(body: str, item: str) -> tuple[Any, ...]:
    try:
        values = tuple(load_yaml(v.strip()) for v in body.split(","))
    except yaml.YAMLError:
        raise InputError(f"--vary {item}: a listed value is not valid YAML") from None
    if any(v is None for v in values):
        raise InputError(f"--vary {item}: empty value in the list")
    return values


def parse_vary(item: str) -> Variation:
    """Parse one ``KEY=DIST``; InputError with a one-line reason on anything else."""
    key, sep, dist = item.partition("=")
    key, dist = key.strip(), dist.strip()
    if not sep or not key or not dist:
        raise InputError(f"--vary {item}: expected KEY=DIST (e.g. rig.floor_masses=±10%)")
    kind, colon, body = dist.partition(":")
    if colon and kind in RELATIVE:
        return Variation(key, kind, _percent(body, item))
    if colon and kind == "grid":
        return Variation(key, "grid", values=_grid(body, item))
    if dist.endswith("%") and "," not in dist:
        return Variation(key, "uniform", _percent(dist, item))
    call = re.match(r"\s*([A-Za-z_]\w*)\s*\(", dist)
    if call:
        raise InputError(f"--vary {item}: {call.group(1)}(...) is not a distribution; write "
                         "uniform:±P%, normal:P%, grid:lo:hi:n, or a list a,b,c")
    if colon and kind.isidentifier() and "," not in kind:
        raise InputError(f"--vary {item}: unknown distribution {kind!r} "
                         "(uniform:±P%, normal:P%, grid:lo:hi:n, or a list a,b,c)")
    return Variation(key, "list", values=_listed(dist, item))


def lookup(scene: dict[str, Any], key: str) -> Any:
    """The value at a dotted key of a scene dict; InputError naming the key if absent."""
    node: Any = scene
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise InputError(f"--vary {key}: the scene has no such key")
        node = node[part]
    return node


def check_nominal(variation: Variation, nominal: Any) -> None:
    """Relative spreads need a number or a list of numbers."""
    if variation.discrete:
        return
    numbers = nominal if isinstance(nominal, list) else [nominal]
    if not numbers or not all(isinstance(v, int | float) and not isinstance(v, bool)
                              for v in numbers):
        raise InputError(f"--vary {variation.key}: a relative spread needs a numeric value "
                         f"(the scene has {nominal!r})")


def perturb(variation: Variation, nominal: Any, rng: np.random.Generator) -> Any:
    """A relatively perturbed copy of ``nominal`` (element-wise for lists), as floats."""
    shape = len(nominal) if isinstance(nominal, list) else None
    if variation.kind == "uniform":
        factor = 1.0 + rng.uniform(-variation.spread, variation.spread, size=shape)
    else:
        factor = 1.0 + rng.normal(0.0, variation.spread, size=shape)
    value = np.asarray(nominal, dtype=float) * factor
    return value.tolist() if shape is not None else float(value)


def combinations(variations: list[Variation]) -> list[tuple[Any, ...]]:
    """The Cartesian product of the discrete variations' values (one empty tuple if none)."""
    return list(itertools.product(*(v.values for v in variations if v.discrete)))


def draw(variations: list[Variation], nominals: dict[str, Any], index: int,
         rng: np.random.Generator) -> dict[str, Any]:
    """The values of run ``index``: its discrete combination and fresh relative draws."""
    combos = combinations(variations)
    combo = iter(combos[index % len(combos)])
    return {v.key: next(combo) if v.discrete else perturb(v, nominals[v.key], rng)
            for v in variations}


def as_overrides(values: dict[str, Any]) -> list[str]:
    """``KEY=VALUE`` strings for :func:`stillframe.config.scene.scene_from_dict` (JSON is YAML)."""
    return [f"{key}={json.dumps(value)}" for key, value in values.items()]
