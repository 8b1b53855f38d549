"""The identification and integration cores give the same numbers whatever OpenBLAS kernel and
thread count run them (issue 37, "Must show" 1).

Each set-up runs ``tests/support/numerics_probe.py`` in its own process (OpenBLAS reads
``OPENBLAS_CORETYPE`` and ``OPENBLAS_NUM_THREADS`` when it loads). A kernel or a thread count
changes the order of floating-point sums, so results may differ by round-off amplified by the
problem's conditioning, and by no more. The tolerances are those bounds, computed here from
the probe's own numbers:

- identification: the least-squares perturbation bound (Golub & Van Loan, *Matrix
  Computations*, 4th ed., Thm 5.3.1) ``ε (2 κ + κ² tan θ)`` with κ the condition number of the
  refinement's column-normalised Jacobian, tan θ ≈ the residual's share of the data, ε the unit
  round-off times ``sqrt(N m)`` (rounding in sums of N m terms), plus the search's own
  resolution (``XTOL`` times ``sqrt(p)``, the step criterion on the whole scaled parameter
  vector); a damping ratio's relative error is a frequency's divided by ζ
  (``Δζ ≈ |Δλ_c| / |λ_c|``);
- integration: an RK4 step is the linear map M on the linearised model, so round-off ``δ``
  injected at each step reaches the final state through ``M^k``: the difference is at most
  ``Σ_k ‖M^k‖₂ · γ ε max‖x‖`` with γ = 4 stages × 2n operations per component.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from stillframe.identification.pem import XTOL
from stillframe.locations import REPO_ROOT

pytestmark = pytest.mark.processes

SETUPS = {
    "1 thread": {"OPENBLAS_NUM_THREADS": "1"},
    "2 threads": {"OPENBLAS_NUM_THREADS": "2"},
    "Haswell": {"OPENBLAS_CORETYPE": "Haswell"},
    "SkylakeX": {"OPENBLAS_CORETYPE": "SkylakeX"},
    "Zen": {"OPENBLAS_CORETYPE": "Zen"},
}
EPS = np.finfo(float).eps / 2


def probe(settings: dict[str, str]) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OPENBLAS_CORETYPE", "OMP_NUM_THREADS")}
    done = subprocess.run([sys.executable, "-m", "tests.support.numerics_probe"], cwd=REPO_ROOT,
                          env=env | settings, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.fixture(scope="module")
def runs() -> dict[str, dict]:
    return {name: probe(settings) for name, settings in SETUPS.items()}


def test_identification_is_the_same_on_every_blas(runs: dict[str, dict]) -> None:
    ref = runs["1 thread"]["identification"]
    assert ref["converged"]
    f_ref, z_ref = np.array(ref["frequency_hz"]), np.array(ref["damping_ratio"])
    kappa, tan_theta = ref["condition"], ref["residual_share"]
    samples, outputs = 1024, 3
    parameters = ref["parameters"]  # the identifiable ones (the Jacobian's rank)
    bound = (EPS * np.sqrt(samples * outputs) * (2 * kappa + kappa**2 * tan_theta)
             + XTOL * np.sqrt(parameters))
    assert bound < 1e-9  # the target for the same data in other units
    for name, run in runs.items():
        got = run["identification"]
        assert got["converged"] and got["noise_model"] == ref["noise_model"], name
        np.testing.assert_allclose(got["frequency_hz"], f_ref, rtol=bound, atol=0, err_msg=name)
        np.testing.assert_allclose(got["damping_ratio"], z_ref, rtol=bound / z_ref.min(), atol=0,
                                   err_msg=name)


def test_integration_is_the_same_on_every_blas(runs: dict[str, dict]) -> None:
    ref = runs["1 thread"]["integration"]
    states = np.array(ref["states"])
    M = np.array(ref["step_matrix"])
    power, growth = np.eye(M.shape[0]), 0.0
    for _ in range(states.shape[0]):
        growth += np.linalg.norm(power, 2)
        power = M @ power
    bound = growth * 4 * M.shape[0] * EPS * np.max(np.abs(states))
    for name, run in runs.items():
        got = np.array(run["integration"]["states"])
        assert np.max(np.abs(got - states)) <= bound, (name, np.max(np.abs(got - states)), bound)
