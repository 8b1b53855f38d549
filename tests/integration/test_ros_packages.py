"""The ROS 2 packages: valid format-3 package.xml (catkin_pkg) and ament_python set-up."""

from __future__ import annotations

import ast
import configparser
import re
import subprocess
import sys
import tomllib

import pytest
from catkin_pkg.package import parse_package

from stillframe.locations import REPO_ROOT

ROOT = REPO_ROOT
PACKAGES = ("sim_node", "estimator_node", "controller_node", "identification")
NODES = ("sim_node", "estimator_node", "controller_node")


@pytest.mark.parametrize("name", PACKAGES)
def test_package_xml_is_valid_format_3_ament_python(name: str) -> None:
    package = parse_package(str(ROOT / name / "package.xml"))
    package.validate()
    assert package.name == name
    assert package.package_format == 3
    assert [(e.tagname, e.content) for e in package.exports] == [("build_type", "ament_python")]
    assert (ROOT / name / "resource" / name).is_file()
    assert (ROOT / "ros_ws" / "src" / name).resolve() == (ROOT / name).resolve()


@pytest.mark.parametrize("name", NODES)
def test_ros2_run_finds_the_console_script(name: str) -> None:
    """`ros2 run PKG EXE` looks in lib/PKG: setup.cfg must install the script there."""
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / name / "setup.cfg")
    assert cfg["develop"]["script_dir"] == f"$base/lib/{name}"
    assert cfg["install"]["install_scripts"] == f"$base/lib/{name}"
    scripts = cfg["options.entry_points"]["console_scripts"].split()
    assert scripts == [name, "=", f"{name}.node:main"]


def test_identification_installs_identify_bag_and_modal_tracker() -> None:
    """The identification package's two executables, where `ros2 run` looks (lib/PKG)."""
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "identification" / "setup.cfg")
    assert cfg["install"]["install_scripts"] == "$base/lib/identification"
    scripts = cfg["options.entry_points"]["console_scripts"].split()
    assert scripts == ["identify_bag", "=", "identification.identify_bag:main",
                       "modal_tracker", "=", "identification.node:main"]


#: rosdep keys of the third-party libraries the packages import
ROSDEP_KEYS = {"numpy": "python3-numpy", "scipy": "python3-scipy",
               "matplotlib": "python3-matplotlib", "pandas": "python3-pandas",
               "yaml": "python3-yaml"}
#: every module of a package imported in a fresh interpreter: which workspace packages it loads
LOADED = """
import importlib, pkgutil, sys
name = sys.argv[1]
package = importlib.import_module(name)
for module in pkgutil.iter_modules(package.__path__):
    if module.name not in ("setup", "__main__"):
        importlib.import_module(f"{name}.{module.name}")
print(" ".join(sorted({m.split(".")[0] for m in sys.modules} & set(sys.argv[2:]))))
"""


def imported_names(name: str) -> set[str]:
    """Top-level names of every import statement in the package's modules (not setup.py)."""
    names = set()
    for path in (ROOT / name).glob("*.py"):
        if path.name == "setup.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names.add(node.module.split(".")[0])
    return names - set(sys.stdlib_module_names) - {name}


@pytest.mark.parametrize("name", PACKAGES)
def test_package_xml_declares_what_the_package_imports(name: str) -> None:
    """exec_depend = the workspace packages its modules load (directly or through stillframe),
    stillframe, and the rosdep keys of the libraries it imports; the libraries without a rosdep
    key come with stillframe's pip install (pyproject dependencies)."""
    loaded = subprocess.run([sys.executable, "-c", LOADED, name, *PACKAGES], cwd=ROOT,
                            capture_output=True, text=True, timeout=60, check=True)
    workspace = set(loaded.stdout.split()) - {name}
    imported = imported_names(name)
    declared = {d.name for d in parse_package(str(ROOT / name / "package.xml")).exec_depends}
    assert declared == (workspace | {"stillframe"}
                        | {ROSDEP_KEYS[n] for n in imported if n in ROSDEP_KEYS})
    pip_only = imported - set(ROSDEP_KEYS) - set(PACKAGES) - {"stillframe"}
    requirements = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    def normal(project: str) -> str:     # PEP 503: lazy_loader is the project lazy-loader
        return re.sub(r"[-_.]+", "-", project).lower()

    assert {normal(n) for n in pip_only} <= {normal(re.split(r"[<>=!~ ]", r)[0])
                                            for r in requirements["dependencies"]}


def test_the_docs_list_each_package_xmls_exec_depends() -> None:
    """docs/launch.md's table of ``exec_depend`` is each package.xml's list, in its order."""
    page = (ROOT / "docs" / "launch.md").read_text()
    table = page[page.index("| package | `exec_depend` |"):]
    rows = {}
    for line in table.splitlines()[2:]:
        if not line.startswith("| `"):
            break
        package, depends = (cell.strip() for cell in line.strip("|").split("|"))
        rows[package.strip("`")] = [d.strip() for d in depends.split(",")]
    assert rows == {name: [d.name for d in parse_package(
        str(ROOT / name / "package.xml")).exec_depends] for name in PACKAGES}
