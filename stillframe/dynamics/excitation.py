"""Excitation forces on a floor as functions of time (the scene's ``excitation`` section).

- ``harmonics``: F(t) = Σ Aᵢ sin(2π fᵢ t + ψᵢ) — the thesis's worst case is 0.1 N at 1.9, 5.7
  and 8.8 Hz on floor 1 (§5.6).
- ``hammer``: a half-sine pulse of the given impulse and width, as an instrumented hammer.
- ``white_noise``: Gaussian force held over 1/rate_hz (a shaker driven by sampled noise).
- ``chirp``: linear sweep from f0 to f1 over ``sweep_s``, then zero.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from stillframe.config.scene import Excitation

Force = Callable[[float], float]


def harmonics(amplitudes: Sequence[float], frequencies_hz: Sequence[float],
              phases: Sequence[float]) -> Force:
    """F(t) = Σ Aᵢ sin(2π fᵢ t + ψᵢ) [N] (phases 0 when none are given)."""
    terms = list(zip(amplitudes, [2.0 * math.pi * f for f in frequencies_hz],
                     phases or [0.0] * len(amplitudes), strict=True))
    return lambda t: sum(a * math.sin(w * t + psi) for a, w, psi in terms)


def hammer(impulse: float, time: float, width: float) -> Force:
    """A half-sine pulse F(t) [N] from ``time`` over ``width`` [s] whose integral is ``impulse`` [N
    s], 0 elsewhere."""
    peak = np.pi * impulse / (2.0 * width)  # ∫ peak sin(π s / width) ds over [0, width] = impulse

    def force(t: float) -> float:
        s = t - time
        return float(peak * np.sin(np.pi * s / width)) if 0.0 <= s <= width else 0.0

    return force


def white_noise(std: float, rate_hz: float, seed: int, duration: float) -> Force:
    """Value i holds over [i, i + 1) / rate_hz; a time k / rate_hz computed in floating point
    (k · period) counts as the start of value k even when ``t * rate_hz`` rounds just below k."""
    samples = np.random.default_rng(seed).normal(0.0, std, int(np.ceil(duration * rate_hz)) + 2)
    return lambda t: (float(samples[min(int(t * rate_hz * (1.0 + 1e-12)), samples.size - 1)])
                      if t >= 0 else 0.0)


def chirp(amplitude: float, f0_hz: float, f1_hz: float, sweep_s: float) -> Force:
    """A linear sweep ``amplitude`` sin(2π (f0 t + ½ (f1 − f0)/T t²)) [N] over [0, ``sweep_s``], 0
    after."""
    rate = (f1_hz - f0_hz) / sweep_s

    def force(t: float) -> float:
        if not 0.0 <= t <= sweep_s:
            return 0.0
        return float(amplitude * np.sin(2.0 * np.pi * (f0_hz * t + 0.5 * rate * t * t)))

    return force


def excitation_force(excitation: Excitation, duration: float) -> Force | None:
    """The scalar force of the scene's excitation, or None for ``type: none``."""
    e = excitation
    match e.type:
        case "harmonics":
            return harmonics(e.amplitudes, e.frequencies_hz, e.phases)
        case "hammer":
            return hammer(e.impulse, e.time, e.width)
        case "white_noise":
            return white_noise(e.std, e.rate_hz, e.seed, duration)
        case "chirp":
            return chirp(e.amplitude, e.f0_hz, e.f1_hz, e.sweep_s)
    return None


@dataclass(frozen=True)
class FloorLoad:
    """Floor forces (f1, f2, f3) at time t: the excitation's force on ``excitation.floor``.

    Keeps the ``excitation`` section so that compiled integrators
    (:mod:`stillframe.dynamics.kernels`) can evaluate the same force without calling back into
    Python.
    """

    excitation: Excitation
    force: Force

    def __call__(self, t: float) -> np.ndarray:
        f = np.zeros(3)
        f[self.excitation.floor - 1] = self.force(t)
        return f

    def force_at(self, times: np.ndarray) -> np.ndarray:
        """The force at each of ``times`` (harmonics vectorised; the same values as
        ``force`` to round-off)."""
        e = self.excitation
        if e.type == "harmonics":
            w = 2.0 * np.pi * np.asarray(e.frequencies_hz)
            phases = np.asarray(e.phases or [0.0] * len(w))
            return np.sin(np.multiply.outer(times, w) + phases) @ np.asarray(e.amplitudes)
        return np.vectorize(self.force, otypes=[float])(times)


def floor_load(excitation: Excitation, duration: float) -> FloorLoad | None:
    """The scene's floor load, or None for ``type: none``."""
    force = excitation_force(excitation, duration)
    return None if force is None else FloorLoad(excitation, force)
