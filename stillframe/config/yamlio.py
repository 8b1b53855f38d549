"""YAML loading that reads ``1e-3`` as a number (PyYAML's YAML 1.1 resolver reads it as text)
and refuses what strict loaders refuse.

- A key given twice in one mapping is an error naming the key and its line, as in strict YAML
  loaders (ruamel.yaml's default, yaml-cpp, YAML 1.2 itself), where PyYAML keeps the last value
  silently. Merge keys (``<<``) may still be overridden.
- Text nested more deeply than :data:`MAX_DEPTH` levels, and integers beyond Python's digit
  limit, are :class:`yaml.YAMLError` too, so every caller reports them as bad YAML in one line.
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


class _Loader(yaml.SafeLoader):
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
