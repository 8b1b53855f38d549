"""The ROS 2 packages: valid format-3 package.xml (catkin_pkg) and ament_python set-up."""

from __future__ import annotations

import configparser
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

ROOT = Path(__file__).resolve().parents[1]
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
