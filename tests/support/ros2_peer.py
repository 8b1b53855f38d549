"""The real ROS 2 Jazzy command line (ros2cli, launch_ros) as a peer of the tests.

It is not a dependency: it lives in a virtual environment of its own (docs/launch.md, "The real
Jazzy command line beside the tests", says how to install it), found through
``STILLFRAME_ROS2_PEER`` (that environment's directory) or a ``ros2`` on ``PATH``. A test that
needs it asks :func:`ros2_or_skip`, and is skipped with the reason where it is absent. The peer
runs with this process's ROS environment (domain, discovery range) and nothing of the project on
its Python path.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

#: the variable naming the peer's virtual environment
PEER_ENV = "STILLFRAME_ROS2_PEER"


def ros2() -> Path | None:
    """The peer's ``ros2`` executable, None where it is not installed."""
    venv = os.environ.get(PEER_ENV)
    if venv:
        found = Path(venv) / "bin" / "ros2"
        return found if found.is_file() else None
    on_path = shutil.which("ros2")
    return Path(on_path) if on_path else None


def ros2_or_skip() -> Path:
    """:func:`ros2`, or skip the test saying how to install the peer."""
    found = ros2()
    if found is None:
        pytest.skip(f"the real ROS 2 Jazzy command line is not installed: set {PEER_ENV} to "
                    "its virtual environment (docs/launch.md) or put ros2 on PATH")
    return found


def peer_env(**extra: str) -> dict[str, str]:
    """This environment (ROS_DOMAIN_ID, the discovery range) with the peer's ``bin`` first on
    ``PATH`` and no Python path of the project's."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "STILLFRAME_RMW")}
    env["PATH"] = f"{ros2_or_skip().parent}{os.pathsep}{env.get('PATH', '')}"
    return {**env, **extra}


def run_ros2(*args: str, timeout: float = 60, env: dict[str, str] | None = None,
             ) -> subprocess.CompletedProcess:
    """``ros2 ARGS`` to completion (text output)."""
    return subprocess.run([str(ros2_or_skip()), *args], env=env or peer_env(),
                          capture_output=True, text=True, timeout=timeout)
