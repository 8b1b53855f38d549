"""Which backend a process's nodes use (``STILLFRAME_RMW``, else ``rclpy`` when importable, else
``dds``), decided without importing either: the command-line tools ask this before they load a
middleware, and :mod:`stillframe.middleware.api` re-exports it."""

from __future__ import annotations

import importlib.util
import os

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
    return backend


def backend_name() -> str:
    """``STILLFRAME_RMW`` if set, else ``rclpy`` when importable, else ``dds``."""
    chosen = os.environ.get(BACKEND_ENV, "").strip()
    if not chosen:
        return "rclpy" if has_rclpy() else "dds"
    return check_backend(chosen, f"{BACKEND_ENV}={chosen}")
