"""Validation of an identified discrete model against measured data it was not identified on.

The model's output is simulated from the measured input alone (no output feedback); the initial
state is the least-squares fit to the measured output, as in MATLAB's ``compare``, so that an
unknown start does not count against the model. Fit per output (normalised RMS error):
``100 (1 - ||y - ŷ|| / ||y - mean(y)||)`` %.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from stillframe.errors import IdentificationError


def simulate(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, u: np.ndarray,
             x0: np.ndarray | None = None) -> np.ndarray:
    """Output (N, p) of x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k]."""
    x0 = np.zeros(A.shape[0]) if x0 is None else x0
    _, y, _ = signal.dlsim((A, B, C, D, 1.0), u, x0=x0)
    return np.asarray(y).reshape(len(u), C.shape[0])


def free_response(A: np.ndarray, C: np.ndarray, samples: int) -> np.ndarray:
    """Stacked C A^k, k = 0..samples-1: shape (samples, p, n)."""
    out = np.empty((samples, C.shape[0], A.shape[0]))
    CA = C.copy()
    for k in range(samples):
        out[k] = CA
        CA = CA @ A
    return out


def simulate_fitted(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, u: np.ndarray,
                    y: np.ndarray) -> np.ndarray:
    """Simulated output with the initial state that fits ``y`` best in least squares."""
    if np.max(np.abs(np.linalg.eigvals(A))) >= 1:
        raise IdentificationError(
            "the identified model is unstable: it cannot be validated by simulation")
    forced = simulate(A, B, C, D, u)
    obs = free_response(A, C, len(u)).reshape(-1, A.shape[0])
    x0 = np.linalg.lstsq(obs, (y - forced).ravel(), rcond=None)[0]
    return forced + (obs @ x0).reshape(y.shape)


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """Normalised-RMS fit per output column, in percent (100 = perfect, can be negative)."""
    err = np.linalg.norm(y - yhat, axis=0)
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    return 100.0 * (1.0 - err / spread)
