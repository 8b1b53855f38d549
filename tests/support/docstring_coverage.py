"""How many public callables of the library and the node packages have a docstring.

Public: a module-level function or class whose name does not start with ``_``, and each method
or property of such a class (nested classes included) whose name does not start with ``_``.
Run as ``python -m tests.support.docstring_coverage`` from the repository root: it prints the
ratio, and with ``--missing`` each undocumented callable as ``path:line name``.
"""

from __future__ import annotations

import argparse
import ast
from collections.abc import Iterator
from pathlib import Path

from stillframe.locations import REPO_ROOT

PACKAGES = ("stillframe", "sim_node", "estimator_node", "controller_node", "container_node",
            "identification")

Definition = ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef


def public_definitions(body: list[ast.stmt], prefix: str = "") -> Iterator[tuple[str, Definition]]:
    """Each public function, class and method in ``body`` with its dotted name; a class's
    members are walked only when the class is public."""
    for node in body:
        if isinstance(node, Definition) and not node.name.startswith("_"):
            yield prefix + node.name, node
            if isinstance(node, ast.ClassDef):
                yield from public_definitions(node.body, f"{prefix}{node.name}.")


def callables(root: Path = REPO_ROOT) -> Iterator[tuple[Path, str, Definition]]:
    """``(path, dotted name, node)`` for every public callable of :data:`PACKAGES` under
    ``root``."""
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            for name, node in public_definitions(tree.body):
                yield path, name, node


def coverage(root: Path = REPO_ROOT) -> tuple[int, int, list[str]]:
    """``(documented, total, missing)``, with ``missing`` as ``path:line name`` lines."""
    documented = total = 0
    missing = []
    for path, name, node in callables(root):
        total += 1
        if ast.get_docstring(node):
            documented += 1
        else:
            missing.append(f"{path.relative_to(root)}:{node.lineno} {name}")
    return documented, total, missing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--missing", action="store_true", help="list the undocumented ones")
    args = parser.parse_args()
    documented, total, missing = coverage()
    if args.missing:
        print("\n".join(missing))
    print(f"{documented} of {total} public callables documented ({documented / total:.1%})")


if __name__ == "__main__":
    main()
