"""YAML that would exhaust memory or recursion once expanded (``config/yamlio.py``): alias bombs
of every width and depth, self-referring aliases, chains of aliases deeper than the nesting
bound, refused before anything is built from them; documents with aliases inside the bounds
load as their expansion; messages stay short whatever the value (``config/schema.show``)."""

from __future__ import annotations

import itertools
import json
import random

import pytest
import yaml

from stillframe.config.scene import scene_from_dict
from stillframe.config.schema import show
from stillframe.config.yamlio import MAX_DEPTH, MAX_NODES, check_expansion, load_yaml
from stillframe.errors import InputError


def bomb(width: int, depth: int, *, flow: bool = True) -> str:
    """``name:`` holding ``depth`` levels of ``width`` aliases each of the level below: about
    width ** depth values once expanded, in a few hundred bytes."""
    if flow:
        value = "&a0 [" + ", ".join(['"lol"'] * width) + "]"
        for level in range(1, depth + 1):
            value = f"&a{level} [{value}, " + ", ".join([f"*a{level - 1}"] * (width - 1)) + "]"
        return f"name: {value}\n"
    lines = ["a0: &a0 [" + ", ".join(['"lol"'] * width) + "]"]
    lines += [f"a{level}: &a{level} [" + ", ".join([f"*a{level - 1}"] * width) + "]"
              for level in range(1, depth + 1)]
    return "\n".join(lines) + "\n"


def expanded(width: int, depth: int) -> int:
    """Values of :func:`bomb` once expanded: a list of ``width`` at each level, strings last."""
    return sum(width ** k for k in range(depth + 2))


@pytest.mark.parametrize(("width", "depth"), [
    (w, d) for w, d in itertools.product((2, 3, 9, 50), range(2, 40))
    if expanded(w, d) > MAX_NODES][::7])
def test_alias_bombs_are_refused_before_they_expand(width: int, depth: int) -> None:
    for text in (bomb(width, depth), bomb(width, depth, flow=False)):
        assert len(text) < 20_000
        with pytest.raises(yaml.YAMLError, match=f"more than {MAX_NODES} values with its "
                                                 "aliases expanded"):
            load_yaml(text)


def test_the_bound_is_on_the_expansion_not_on_aliases() -> None:
    """Under the bound an alias document loads as the same values written out; at the bound a
    document passes, one value more is refused (checked on composed nodes: PyYAML takes a
    minute to parse a million values written out)."""
    width, depth = 4, 6                 # 5461 values expanded
    assert expanded(width, depth) <= MAX_NODES
    data = load_yaml(bomb(width, depth, flow=False))
    assert data == load_yaml(json.dumps(data))      # the same with the aliases written out
    one = yaml.ScalarNode("tag:yaml.org,2002:int", "1")
    at_bound = yaml.SequenceNode("tag:yaml.org,2002:seq", [one] * (MAX_NODES - 1))
    check_expansion(at_bound)                     # the list and its items: MAX_NODES values
    at_bound.value.append(one)
    with pytest.raises(yaml.YAMLError, match=f"more than {MAX_NODES} values"):
        check_expansion(at_bound)


def test_aliases_that_hold_themselves_are_refused() -> None:
    for text in ("a: &x [1, *x]\n", "a: &x {b: *x}\n", "a: &x [[[*x]]]\n",
                 "a: &x [&y [*x], *y]\n"):
        with pytest.raises(yaml.YAMLError, match="an alias that holds itself"):
            load_yaml(text)


def test_a_chain_of_aliases_deeper_than_the_nesting_bound_is_refused() -> None:
    """Each line nests two levels; expanded, the chain nests one level per line, past the bound
    at which the text itself is refused (and Python's recursion limit)."""
    lines = ["a0: &a0 [1]"] + [f"a{k}: &a{k} [*a{k - 1}]" for k in range(1, 3 * MAX_DEPTH)]
    with pytest.raises(yaml.YAMLError, match=f"nested more than {MAX_DEPTH} levels deep with "
                                             "its aliases expanded"):
        load_yaml("\n".join(lines))
    load_yaml("\n".join(lines[:MAX_DEPTH - 2]))          # within the bound: loads


def test_merge_keys_and_shared_values_still_load() -> None:
    """Anchors as scenes use them: a merged section, a list used twice."""
    data = load_yaml("base: &b {x: 1, y: [1, 2]}\nother:\n  <<: *b\n  x: 2\nz: *b\n")
    assert data == {"base": {"x": 1, "y": [1, 2]}, "other": {"x": 2, "y": [1, 2]},
                    "z": {"x": 1, "y": [1, 2]}}


def test_a_bomb_in_every_text_key_of_a_scene_is_one_line() -> None:
    """The issue's keys (``integrator:``, ``name:``, ``description:``) and a generated
    sample of others, each given a bomb through ``--set``: one short InputError."""
    rng = random.Random(38)
    for key in ["integrator", "name", "description", "integrator.method",
                *rng.sample(["rig", "model.type", "controller", "plant.file"], 2)]:
        with pytest.raises(InputError) as caught:
            scene_from_dict({"name": "x"}, [f"{key}={bomb(9, 9).removeprefix('name: ')}"])
        message = str(caught.value)
        assert "\n" not in message and len(message) < 300, message
        assert "aliases expanded" in message


def test_show_cuts_before_it_formats() -> None:
    """A value of 9 ** 12 elements by shared references (what an alias bomb builds), a
    3000-deep list, a 5000-digit number, a 10 MB string: each a short line."""
    huge: list = ["lol"] * 9
    for _ in range(12):
        huge = [huge] * 9
    deep: list = []
    for _ in range(3000):
        deep = [deep]
    for value in (huge, deep, 10**5000, "x" * 10_000_000, {"k": huge}):
        text = show(value)
        assert len(text) <= 60, text
    assert show("a" * 100, quote=False) == "a" * 59 + "…"
    assert show([1, 2, 3]) == "[1, 2, 3]"
