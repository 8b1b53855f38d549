"""YAML loading that reads ``1e-3`` as a number (PyYAML's YAML 1.1 resolver reads it as text)
and refuses what strict loaders refuse.

- A key given twice in one mapping is an error naming the key and its line, as in strict YAML
  loaders (ruamel.yaml's default, yaml-cpp, YAML 1.2 itself), where PyYAML keeps the last value
  silently. Merge keys (``<<``) may still be overridden.
- Text nested more deeply than :data:`MAX_DEPTH` levels, and integers beyond Python's digit
  limit, are :class:`yaml.YAMLError` too, so every caller reports them as bad YAML in one line.
- Aliases are expanded in the count: a document that, expanded, holds more than
  :data:`MAX_NODES` values or nests more than :data:`MAX_DEPTH` levels, or that refers to
  itself, is refused before anything is built from it. PyYAML builds an alias as a reference to
  the one object, so a few hundred bytes (the "billion laughs") load at once into a value whose
  first walk (a check, a message, a copy) takes minutes and all the memory there is.
- Bytes are decoded as the YAML spec says: UTF-8, or UTF-16 with its byte-order mark.
"""

from __future__ import annotations

import re
import sys
from typing import Any

import yaml
from yaml.constructor import ConstructorError

#: nesting depth of mappings and lists at most (PyYAML composes recursively)
MAX_DEPTH = 200
#: the size of a YAML file a person writes (a scene, a parameter file, a model in YAML) at most
MAX_YAML_BYTES = 1 << 20
#: values (scalars, lists, mappings) of a document with its aliases expanded, at most: more than
#: a file of :data:`MAX_YAML_BYTES` holds without aliases (two bytes a value: ``1,``)
MAX_NODES = MAX_YAML_BYTES


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    return list(node.value) if isinstance(node, yaml.SequenceNode) else []


def check_expansion(root: yaml.Node) -> None:
    """ComposerError when ``root`` with its aliases expanded holds more than :data:`MAX_NODES`
    values, nests deeper than :data:`MAX_DEPTH`, or holds itself. Each node is visited once
    (its expanded size and depth kept), without recursion."""
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    open_ids: set[int] = set()              # the nodes on the current path
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, finished = stack.pop()
        key = id(node)
        kids = _children(node)
        if finished:
            open_ids.discard(key)
            size[key] = 1 + sum(size[id(k)] for k in kids)
            depth[key] = 1 + max((depth[id(k)] for k in kids), default=0)
            problem = (f"more than {MAX_NODES} values with its aliases expanded"
                       if size[key] > MAX_NODES else
                       f"nested more than {MAX_DEPTH} levels deep with its aliases expanded"
                       if depth[key] > MAX_DEPTH else None)
            if problem:
                raise yaml.composer.ComposerError(None, None, problem, node.start_mark)
            continue
        if key in size:
            continue
        open_ids.add(key)
        stack.append((node, True))
        for kid_id, kid in {id(kid): kid for kid in kids}.items():
            if kid_id in open_ids:
                raise yaml.composer.ComposerError(None, None, "an alias that holds itself",
                                                  kid.start_mark)
            if kid_id not in size:
                stack.append((kid, False))


class _Loader(yaml.SafeLoader):
    def construct_document(self, node: Any) -> Any:
        check_expansion(node)
        return super().construct_document(node)

    def compose_node(self, parent: Any, index: Any) -> Any:
        self._depth = getattr(self, "_depth", 0) + 1
        try:
            if self._depth > MAX_DEPTH:
                mark = self.peek_token().start_mark
                raise yaml.composer.ComposerError(
                    None, None, f"nested more than {MAX_DEPTH} levels deep", mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: set[Any] = set()
            for key_node, _value in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                except TypeError:
                    continue        # unhashable: the base class says so
                if duplicate:
                    raise ConstructorError("while constructing a mapping", node.start_mark,
                                           f"found duplicate key {key!r}", key_node.start_mark)
                seen.add(key)
        return super().construct_mapping(node, deep)


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


_QUOTED = re.compile(rb""""(?:[^"\\\n]|\\.)*"|'[^'\n]*'""")
_BRACKETS = re.compile(rb"[\[\]{}]")


def _flow_depth(raw: bytes) -> int:
    """The most ``[``/``{`` open at once outside quoted strings. PyYAML's scanner keeps a
    possible simple key per open flow level and walks them all on every token, so deep flow
    nesting costs it quadratic time (0.6 s at 3000 levels; a 1 MiB line would hang it): it is
    refused before parsing."""
    depth = deepest = 0
    for match in _BRACKETS.finditer(_QUOTED.sub(b"", raw)):
        depth = depth + 1 if match.group() in b"[{" else max(0, depth - 1)
        deepest = max(deepest, depth)
    return deepest


def load_yaml(text: str | bytes) -> Any:
    """Parse YAML text (or bytes: UTF-8, UTF-16 with a byte-order mark) with scientific notation
    read as floats; :class:`yaml.YAMLError` on anything that is not strict YAML."""
    raw = text.encode("utf-8", "surrogateescape") if isinstance(text, str) else text
    if _flow_depth(raw.replace(b"\0", b"")) > MAX_DEPTH:
        raise yaml.YAMLError(f"nested more than {MAX_DEPTH} levels deep")
    try:
        return yaml.load(text, Loader=_Loader)
    except RecursionError:
        raise yaml.YAMLError(f"nested too deeply (Python's recursion limit "
                             f"{sys.getrecursionlimit()})") from None
    except ValueError as exc:      # an integer beyond Python's digit limit
        raise yaml.YAMLError(str(exc).split(";")[0]) from None
    except MemoryError:
        raise yaml.YAMLError("does not fit in the memory this process may take") from None


def problem(exc: yaml.YAMLError) -> str:
    """One line on what is wrong with the YAML and where: ``found duplicate key 'duration' at
    line 3``."""
    if isinstance(exc, yaml.reader.ReaderError):
        kind = "a control character" if exc.encoding == "unicode" else \
            "not UTF-8 or UTF-16 text"
        return f"{kind} (byte {exc.position}: {exc.reason})"
    mark = getattr(exc, "problem_mark", None)
    what = getattr(exc, "problem", None) or (str(exc).splitlines() or ["not valid YAML"])[0]
    return f"{what}{f' at line {mark.line + 1}' if mark else ''}"
