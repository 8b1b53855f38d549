"""Public functions with many options take them by keyword: a call cannot swap two options of
one type silently (``limit`` and ``actuator_limit`` were once such a pair). The library's public
functions and methods take at most :data:`MAX_POSITIONAL_OPTIONS` parameters with a default
positionally; the rest are keyword-only (after ``*``)."""

from __future__ import annotations

import ast

from stillframe.locations import REPO_ROOT

#: options (parameters with a default) a public callable may take positionally
MAX_POSITIONAL_OPTIONS = 3
SOURCES = ("stillframe", "sim_node", "estimator_node", "controller_node", "container_node",
           "identification")


def too_many_positional_options(source: str, where: str) -> dict[str, int]:
    """``where:line name`` of each public function in ``source`` taking more than the maximum
    options positionally, with its count."""
    found = {}
    for node in ast.walk(ast.parse(source)):
        if (isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
                and not node.name.startswith("_")
                and len(node.args.defaults) > MAX_POSITIONAL_OPTIONS):
            found[f"{where}:{node.lineno} {node.name}"] = len(node.args.defaults)
    return found


def test_many_options_are_keyword_only() -> None:
    found: dict[str, int] = {}
    for package in SOURCES:
        for path in sorted((REPO_ROOT / package).rglob("*.py")):
            found |= too_many_positional_options(path.read_text(),
                                                 str(path.relative_to(REPO_ROOT)))
    assert found == {}


def test_the_check_finds_four_positional_options_and_passes_keyword_ones() -> None:
    source = ("def f(a, b=1, c=2, d=3, e=4):\n    pass\n\n\n"
              "def g(a, b=1, c=2, *, d=3, e=4):\n    pass\n\n\n"
              "def _h(a, b=1, c=2, d=3, e=4):\n    pass\n")
    assert too_many_positional_options(source, "m.py") == {"m.py:1 f": 4}
