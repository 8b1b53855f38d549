"""Every package names its public surface in ``__all__``, lazily (``lazy_loader.attach``, PEP 562):
each name resolves to what its submodule defines, every module of the package is named, and
importing a package imports none of its submodules."""

from __future__ import annotations

import ast
import importlib
import inspect
import subprocess
import sys

import pytest

from stillframe.locations import REPO_ROOT

ROOTS = ("stillframe", "sim_node", "estimator_node", "controller_node", "container_node",
         "identification")
PACKAGES = sorted(".".join(init.parent.relative_to(REPO_ROOT).parts)
                  for root in ROOTS for init in (REPO_ROOT / root).rglob("__init__.py"))
# The one package whose ``__init__`` holds code of its own (``build_model``) and imports what it
# needs for it, eagerly.
EAGER = {"stillframe.dynamics.models"}
#: the ``ros`` extra of pyproject.toml (real rclpy): a machine without it has no rclpy backend
ROS_EXTRA = {"rclpy", "rcl_interfaces"}


def modules_of(package: str) -> list[str]:
    """The modules and subpackages in ``package``'s directory whose names do not start with
    ``_``, less an ament package's build file ``setup.py``."""
    folder = REPO_ROOT.joinpath(*package.split("."))
    return sorted(p.stem if p.is_file() else p.name for p in folder.iterdir()
                  if not p.name.startswith(("_", ".")) and p.name != "setup.py"
                  and (p.suffix == ".py" or (p / "__init__.py").is_file()))


def test_the_packages_are_found() -> None:
    assert {"stillframe", "stillframe.loop", "sim_node", "identification"} <= set(PACKAGES)


@pytest.mark.parametrize("package", PACKAGES)
def test_each_name_in_all_resolves_to_what_its_module_defines(package: str) -> None:
    module = importlib.import_module(package)
    names = module.__all__
    assert names and len(set(names)) == len(names)
    assert sorted(dir(module)) == sorted(names) or package in EAGER
    for name in names:
        try:
            value = getattr(module, name)
        except ModuleNotFoundError as exc:
            if (exc.name or "").split(".")[0] not in ROS_EXTRA:
                raise
            continue
        if inspect.ismodule(value):
            assert value.__name__ == f"{package}.{name}", name
            continue
        home = importlib.import_module(getattr(value, "__module__", "") or package)
        # a name the package re-exports is defined where it says, or in that module's __all__
        assert getattr(home, name) is value, name
        assert home.__name__.startswith(package), (name, home.__name__)


@pytest.mark.parametrize("package", sorted(set(PACKAGES) - EAGER))
def test_every_module_of_a_package_is_named(package: str) -> None:
    """A new module is part of the package's surface; name it in ``submodules`` of the
    package's ``__init__`` (or start its name with ``_``)."""
    module = importlib.import_module(package)
    assert set(modules_of(package)) <= set(module.__all__), \
        sorted(set(modules_of(package)) - set(module.__all__))


def test_importing_a_package_imports_none_of_its_modules() -> None:
    """Each package imported alone, in a fresh interpreter: only it and its parents are new,
    and no numpy (``stillframe --help`` stays light; tests/unit/app/test_cli_dispatch.py)."""
    code = ("import importlib, sys\n"
            "importlib.import_module(sys.argv[1])\n"
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {ROOTS!r}"
            " or m == 'numpy'))")
    for package in sorted(set(PACKAGES) - EAGER):
        done = subprocess.run([sys.executable, "-c", code, package], capture_output=True,
                              text=True, timeout=120, cwd=REPO_ROOT, check=True)
        loaded = ast.literal_eval(done.stdout.splitlines()[-1])
        parents = [".".join(package.split(".")[:i]) for i in range(1, package.count(".") + 2)]
        assert loaded == sorted(parents), (package, loaded)

