"""``colcon build`` of ros_ws/ with colcon from PyPI, and the closed loop run from the install
space: the installed executables (what ``ros2 run PKG EXE`` starts), in an environment made by
sourcing ``install/setup.bash``, give the reductions of ``stillframe closed-loop`` bit for bit."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from catkin_pkg.package import parse_package

from stillframe.locations import REPO_ROOT
from stillframe.loop.closed_loop import run_closed_loop
from tests.support.middleware import finish, run_stillframe
from tests.support.nodes import assert_same_histories, stop
from tests.support.scenes import thesis_scene

pytestmark = pytest.mark.slow

PACKAGES = ("sim_node", "estimator_node", "controller_node", "identification")
#: the executables each package installs into lib/PKG (where ``ros2 run`` looks)
EXECUTABLES = {"sim_node": ["sim_node"], "estimator_node": ["estimator_node"],
               "controller_node": ["controller_node"],
               "identification": ["identify_bag", "modal_tracker"]}
PARAMS = REPO_ROOT / "ros_ws" / "config" / "closed_loop.params.yaml"
SCENE = REPO_ROOT / "scenes" / "thesis_lqg.yaml"
#: ``ros2 run``'s lookup (ros2pkg's get_executable_paths): the package's prefix from the ament
#: index on AMENT_PREFIX_PATH, then the executable files in PREFIX/lib/PKG
RESOLVE = """
import json, os, sys
from ament_index_python.packages import get_package_prefix, get_packages_with_prefixes
found = {}
for name in sys.argv[1:]:
    module = __import__(name)
    prefix = get_package_prefix(name)
    lib = os.path.join(prefix, "lib", name)
    found[name] = {"prefix": prefix, "module": module.__file__, "executables": sorted(
        f for f in (os.listdir(lib) if os.path.isdir(lib) else [])
        if os.access(os.path.join(lib, f), os.X_OK))}
print(json.dumps({"packages": sorted(get_packages_with_prefixes()), "found": found}))
"""


@pytest.fixture(scope="module")
def install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``colcon build --base-paths ros_ws/src`` with build, install and log under a tmp dir."""
    work = tmp_path_factory.mktemp("colcon")
    done = subprocess.run(
        [sys.executable, "-m", "colcon", "--log-base", str(work / "log"), "build",
         "--base-paths", str(REPO_ROOT / "ros_ws" / "src"), "--build-base", str(work / "build"),
         "--install-base", str(work / "install")],
        cwd=work, env=workspace_env(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return work / "install"


@pytest.fixture(scope="module")
def one_process() -> dict:
    """``stillframe closed-loop scenes/thesis_lqg.yaml --json``: the independent reference."""
    done = run_stillframe("closed-loop", str(SCENE), "--json", timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def workspace_env() -> dict[str, str]:
    """This environment without any Python or ament path: only what setup.bash adds counts."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    for name in ("PYTHONPATH", "AMENT_PREFIX_PATH", "COLCON_PREFIX_PATH"):
        env.pop(name, None)
    return env


def sourced(install: Path, command: str) -> list[str]:
    """``bash -c 'source install/setup.bash && COMMAND'``."""
    return ["bash", "-c", f'source "{install}/setup.bash" && {command}']


def test_each_package_is_installed_with_its_package_xml(install: Path) -> None:
    for name in PACKAGES:
        share = install / name / "share"
        installed = parse_package(str(share / name / "package.xml"))
        source = parse_package(str(REPO_ROOT / name / "package.xml"))
        assert installed.name == name
        assert ([d.name for d in installed.exec_depends]
                == [d.name for d in source.exec_depends])
        assert (share / "ament_index" / "resource_index" / "packages" / name).is_file()


def test_sourced_install_space_finds_packages_and_executables_like_ros2_run(
        install: Path, tmp_path: Path) -> None:
    """After ``source install/setup.bash`` the ament index lists the four packages at their
    install prefixes, each package's modules import from its install space (not the source
    tree), and lib/PKG holds exactly the package's executables."""
    done = subprocess.run(
        [*sourced(install, f'"{sys.executable}" -c "$0" "$@"'), RESOLVE, *PACKAGES],
        cwd=tmp_path, env=workspace_env(), capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert set(PACKAGES) <= set(report["packages"])
    for name in PACKAGES:
        found = report["found"][name]
        assert Path(found["prefix"]) == install / name
        assert Path(found["module"]).is_relative_to(install / name / "lib"), found["module"]
        assert found["executables"] == EXECUTABLES[name]


def ros2_run(install: Path, package: str, *args: str) -> list[str]:
    """``ros2 run PKG PKG args`` in the sourced workspace: PREFIX/lib/PKG/PKG with the prefix
    from the ament index (exec: signals reach the node itself)."""
    prefix = (f'"{sys.executable}" -c "from ament_index_python.packages import '
              f'get_package_prefix; print(get_package_prefix(\'{package}\'))"')
    quoted = " ".join(f"'{a}'" for a in args)
    return sourced(install, f'exec "$({prefix})/lib/{package}/{package}" {quoted}')


def start(argv: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(argv, cwd=cwd, env=workspace_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


BACKENDS = ["dds", pytest.param("rclpy", marks=pytest.mark.skipif(
    importlib.util.find_spec("rclpy") is None, reason="rclpy has no wheels for this platform"))]


@pytest.mark.parametrize("backend", BACKENDS)
def test_installed_nodes_close_the_loop_like_one_process(
        install: Path, one_process: dict, tmp_path: Path, backend: str,
        ros_domain: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """sim_node, estimator_node and controller_node started from the install space with the
    workstation's parameter file (ros_ws/config) and an absolute ``scene`` on the full
    thesis_lqg scene, in lock-step: every history equals the one-process loop's, and the
    reductions and peaks the ``stillframe closed-loop`` run's, to the last bit."""
    monkeypatch.setenv("STILLFRAME_RMW", backend)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ros_args = ["--ros-args", "--params-file", str(PARAMS), "-p", f"scene:={SCENE}"]
    peers = [start(ros2_run(install, name, *ros_args), tmp_path)
             for name in ("estimator_node", "controller_node")]
    sim = start(ros2_run(install, "sim_node", *ros_args), tmp_path)
    try:
        _out, sim_err = finish(sim, timeout=300)
    finally:
        codes = [stop(peer) for peer in peers]
    assert sim.returncode == 0, sim_err[-3000:]
    assert f"middleware backend: {backend}" in sim_err
    for code, err in codes:
        assert code == 0, err[-3000:]
    # the parameter file's result_file, relative to the node's working directory
    nodes = json.loads((tmp_path / "closed_loop_result.json").read_text())
    assert nodes["steps"] == one_process["steps"] == 1600
    assert nodes["complete"] is True
    with np.load(tmp_path / "closed_loop_result.npz") as histories:   # sample by sample
        assert_same_histories(histories, run_closed_loop(thesis_scene("thesis_lqg", [])))
    for key in ("reduction_pct", "peak_uncontrolled", "peak_controlled", "peak_command"):
        assert nodes[key] == one_process[key], key
