"""The identification and integration cores on fixed inputs, printed as JSON: run in a fresh
process under one BLAS set-up (``OPENBLAS_CORETYPE``, ``OPENBLAS_NUM_THREADS``) by
``tests/integration/test_numerics_any_blas.py`` and compared across set-ups.

``python -m tests.support.numerics_probe`` prints ``{"identification": {...},
"integration": {...}}`` with the numbers and what the comparison's tolerance needs: the
refinement's Jacobian condition number and the residual's share of the data; the integrator's
step matrix and the largest state.
"""

from __future__ import annotations

import json

import numpy as np

from stillframe.config.scene import scene_from_dict
from stillframe.dynamics.integrators import RK4, integrate
from stillframe.dynamics.models import build_model
from stillframe.dynamics.simulation import initial_state
from stillframe.dynamics.systems import LinearSystem
from stillframe.identification.pipeline import identify
from stillframe.identification.sweep import shear_building, simulate

INTEGRATION_STEP = 1e-3
INTEGRATION_STEPS = 2000


def identification() -> dict:
    """A 3-storey sweep building, 1024 samples at 30 dB, order 6, refined."""
    rec = simulate(shear_building(1), 1024, 30.0, 1)
    ident = identify(rec.u, rec.y, rec.dt, order=6)
    ref = ident.refinement
    return {"frequency_hz": ident.modes.frequency_hz.tolist(),
            "damping_ratio": ident.modes.damping_ratio.tolist(),
            "converged": ref.converged, "condition": ref.condition,
            "noise_model": ref.noise_model, "parameters": ref.parameter_count,
            "residual_share": float(np.linalg.norm(ref.errors) / np.linalg.norm(rec.y))}


def integration() -> dict:
    """RK4 on the linearised lumped model from a displaced start, the final state."""
    scene = scene_from_dict({"name": "probe"}, ["initial.floors=[0.001, -0.002, 0.003]",
                                                 "initial.phi=0.05"])
    model = build_model(scene)
    system = LinearSystem(model.linearized())
    states: list[np.ndarray] = []
    integrate(system, initial_state(model, scene.initial), INTEGRATION_STEP, INTEGRATION_STEPS,
              RK4(), observer=lambda k, t, x: states.append(x.copy()))
    h_a = INTEGRATION_STEP * np.linalg.solve(system.E, system.A)
    term = np.eye(h_a.shape[0])
    step = term.copy()
    for k in range(1, 5):
        term = term @ h_a / k
        step = step + term
    return {"states": np.array(states).tolist(), "step_matrix": step.tolist()}


if __name__ == "__main__":
    print(json.dumps({"identification": identification(), "integration": integration()}))
