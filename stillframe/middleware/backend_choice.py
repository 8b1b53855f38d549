"""Which backend a process's nodes use (``STILLFRAME_RMW``, else ``rclpy`` when importable, else
``dds``), decided without importing either: the command-line tools ask this before they load a
middleware, and :mod:`stillframe.middleware.api` re-exports it."""

from __future__ import annotations

import functools
import importlib.util
import os
import re
import subprocess
import sys

from stillframe.config.environment import value
from stillframe.errors import InputError

BACKEND_ENV = "STILLFRAME_RMW"
BACKENDS = ("dds", "rclpy")


def has_rclpy() -> bool:
    """Whether real rclpy is importable (installed from PyPI by ``stillframe[ros]``)."""
    return importlib.util.find_spec("rclpy") is not None


def check_backend(backend: str, what: str) -> str:
    """``backend`` if it is one of :data:`BACKENDS` and usable here; InputError naming ``what``."""
    if backend not in BACKENDS:
        raise InputError(f"{what}: unknown backend {backend!r} (expected one of "
                         f"{', '.join(BACKENDS)})")
    if backend == "rclpy" and not has_rclpy():
        raise InputError(f"{what}: rclpy cannot be imported here (pip install 'stillframe[ros]', "
                         "or source a ROS 2 Jazzy install)")
    if backend == "rclpy":
        check_rmw_implementation(value("RMW_IMPLEMENTATION"))
    return backend


@functools.cache
def check_rmw_implementation(name: str) -> None:
    """InputError unless rclpy can run on the rmw ``name`` (empty: its default). rcl checks the
    variable when rclpy is imported and ends the process with exit code 102 if it cannot load
    that rmw, so this asks a separate interpreter (once per process, only when it is set)."""
    if not name:
        return
    env = dict(os.environ, RMW_IMPLEMENTATION=name)
    probe = subprocess.run([sys.executable, "-c", "import rclpy.impl.implementation_singleton"],
                           env=env, capture_output=True, text=True, timeout=120)
    if probe.returncode != 0:
        found = re.search(r"instead found '([^']+)'", probe.stderr)
        uses = f" (it runs on {found.group(1)})" if found else ""
        raise InputError(f"RMW_IMPLEMENTATION={name!r}: rclpy here cannot load it{uses}; "
                         f"unset it, or use the dds backend ({BACKEND_ENV}=dds: Cyclone DDS)")


def backend_name() -> str:
    """``STILLFRAME_RMW`` if set, else ``rclpy`` when importable, else ``dds``; the rclpy backend
    checked against ``RMW_IMPLEMENTATION``."""
    chosen = value(BACKEND_ENV) or ("rclpy" if has_rclpy() else "dds")
    return check_backend(chosen, f"{BACKEND_ENV}={chosen}")
