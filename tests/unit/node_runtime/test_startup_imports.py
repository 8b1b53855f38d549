"""What a loop node loads before its scene asks for anything: the controller and the estimator
start without identification, the compiled kernels, scipy.stats or filterpy (each costs a node a
second or so of start-up on a 2-core machine). A scene that needs one loads it when the node is
configured, before its loop runs (a time-varying filter imports filterpy, an adapting estimator
the identification, an EKF or a pH plant the compiled kernels)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from stillframe.locations import REPO_ROOT

#: modules a node's import must not load: what only some scenes need (the work-precision study
#: of ``model.type: auto`` is a lazy module until used: numba and scipy.integrate show it)
HEAVY = ("filterpy", "numba", "scipy.stats", "scipy.integrate", "stillframe.identification.pem",
         "stillframe.loop.adaptation")


@pytest.mark.parametrize("node", ["controller_node", "estimator_node"])
def test_a_node_imports_nothing_only_some_scenes_need(node: str) -> None:
    code = (f"import sys, json; import {node}.node; "
            f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True,
                         text=True, timeout=120, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
