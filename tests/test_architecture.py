"""The layering of docs/architecture.md, enforced: import-linter's contracts (pyproject.toml), no
import cycle between any two modules, and a repository that stands alone."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import grimp
import pytest

from stillframe.locations import REPO_ROOT

ROOT = REPO_ROOT
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")
PACKAGES = ("stillframe", "sim_node", "estimator_node", "controller_node", "container_node")


def lint_imports(cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(LINT_IMPORTS), "--no-cache"], cwd=cwd, capture_output=True,
                          text=True, timeout=120, env={"PYTHONPATH": str(cwd), "PATH": ""})


def test_the_import_contracts_are_kept() -> None:
    done = lint_imports(ROOT)
    assert done.returncode == 0, done.stdout[-3000:]
    assert "7 kept, 0 broken" in done.stdout


def _tree_with(tmp_path: Path, module: str, line: str) -> Path:
    """A copy of the tree where ``module`` (a path under the root) has ``line`` appended."""
    for name in (*PACKAGES, "identification", "pyproject.toml"):
        copy = shutil.copytree if (ROOT / name).is_dir() else shutil.copy
        copy(ROOT / name, tmp_path / name)
    path = tmp_path / module
    path.write_text(path.read_text() + f"\n{line}  # noqa\n")
    return tmp_path


def test_the_contracts_catch_a_core_module_that_imports_a_node(tmp_path: Path) -> None:
    """The check can fail: a copy of the tree where the scene loader imports sim_node breaks
    the first and the layers contract."""
    done = lint_imports(_tree_with(tmp_path, "stillframe/config/scene.py", "import sim_node.node"))
    assert done.returncode == 1
    assert "the ROS-free library never imports a node package BROKEN" in done.stdout
    assert "stillframe.config.scene -> sim_node.node" in done.stdout


def test_the_contracts_catch_a_command_that_imports_a_command(tmp_path: Path) -> None:
    """Commands are leaves: a copy where ``lifecycle`` imports ``param``'s module breaks it."""
    done = lint_imports(_tree_with(tmp_path, "stillframe/app/commands/lifecycle.py",
                                   "import stillframe.app.commands.param"))
    assert done.returncode == 1
    assert "commands are leaves: no command module imports another BROKEN" in done.stdout


def test_the_contracts_catch_the_library_of_the_application_importing_a_benchmark(
        tmp_path: Path) -> None:
    """The launcher below the benchmarks: a copy where it imports one breaks the layers."""
    done = lint_imports(_tree_with(tmp_path, "stillframe/app/launcher.py",
                                   "import stillframe.app.bench.loop"))
    assert done.returncode == 1
    assert "over the application's library BROKEN" in done.stdout


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components with more than one module (iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_tarjan_finds_a_planted_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert strongly_connected(graph) == [["a", "b", "c"]]


def test_no_two_modules_import_each_other_even_inside_functions() -> None:
    """grimp records imports in function bodies and under TYPE_CHECKING as well."""
    graph = grimp.build_graph(*PACKAGES, include_external_packages=False, cache_dir=None)
    imports = {m: set(graph.find_modules_directly_imported_by(m)) for m in graph.modules}
    assert strongly_connected(imports) == []


#: a path beside the checkout, and the design file that stayed outside it (built, so that this file
#: does not itself name them)
OUTSIDE = [os.path.join("..", "shared"), "DESIGN" + ".md"]


@pytest.mark.parametrize("text", OUTSIDE)
def test_the_repository_stands_alone(text: str) -> None:
    """No file points outside the checkout (the seeds are cited by full reference)."""
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True,
                           check=True).stdout.decode().split("\0")
    hits = [f for f in files if f and (ROOT / f).is_file()
            and f.endswith((".py", ".md", ".toml", ".yaml", ".xml", ".cfg", ".txt", ".html"))
            and text in (ROOT / f).read_text(errors="replace")]
    assert hits == []
