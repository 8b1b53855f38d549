"""The thesis's hammer test (§5.5) simulated on a linear model of the rig, and a comparison table.

The record: a blow on floor 1 held for one sample of the load cell (u = impulse / dt, zero-order
hold, so the sampled model is exact), the three floor accelerations, 32 Hz, 2048 samples, white
noise on the load cell and on the accelerometers. The reference modes are the continuous
eigenvalues of the model itself.

``python -m stillframe.identification.hammer [--seeds N]`` prints identified against model
frequencies and damping ratios for OKID + ERA, OKID + ERA/DC and the thesis's combined ERA/DC
variant.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from stillframe.config.scene import load_scene
from stillframe.dynamics.models import LinearModel, build_model
from stillframe.identification.pipeline import identify
from stillframe.locations import SCENES_DIR
from stillframe.text_table import format_table

Array = NDArray[np.float64]
SCENE = SCENES_DIR / "thesis_lumped.yaml"


@dataclass(frozen=True)
class HammerRecord:
    """Input ``u (N, 1)`` [N], output ``y (N, 3)`` [m/s^2], the exact sampled model and the
    model's modes (all of them, pendulum included), ascending."""

    u: Array
    y: Array
    dt: float
    model: tuple[Array, Array, Array, Array]
    frequency_hz: Array
    damping_ratio: Array


def hammer_test(lin: LinearModel, seed: int = 0, *, dt: float = 1.0 / 32.0, samples: int = 2048,
                impulse: float = 0.05, blow_sample: int = 32, force_noise: float = 1e-3,
                acceleration_noise: float = 1e-3) -> HammerRecord:
    """Simulate the hammer test on ``lin`` (input ``f1``, outputs the floor accelerations)."""
    a_c, b_c = lin.state_space()
    n = lin.mass.shape[0]
    floors = [lin.dof_names.index(name) for name in ("x1", "x2", "x3")]
    b_c = b_c[:, :1]
    C, D = a_c[n:][floors], b_c[n:][floors]  # accelerations, thesis eqs. 3.10, 3.11
    A, B, Cd, Dd, _ = signal.cont2discrete((a_c, b_c, C, D), dt, method="zoh")
    u = np.zeros((samples, 1))
    u[blow_sample, 0] = impulse / dt
    _, y, _ = signal.dlsim(signal.StateSpace(A, B, Cd, Dd, dt=dt), u)
    rng = np.random.default_rng(seed)
    lam = np.linalg.eigvals(a_c)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    return HammerRecord(
        u=u + force_noise * rng.standard_normal(u.shape),
        y=y + acceleration_noise * rng.standard_normal(y.shape),
        dt=dt, model=(A, B, Cd, Dd),
        frequency_hz=np.abs(lam) / (2 * np.pi), damping_ratio=-lam.real / np.abs(lam),
    )


def main(argv: list[str] | None = None) -> int:
    """Identify :func:`hammer_test` records of the scene's linearised model (``--seeds`` noise
    realisations) at ``--order`` with OKID/ERA, OKID/ERA-DC, and OKID/ERA-DC on the combined
    parameters, and print each identified mode's frequency and damping beside the model's
    nearest; exit code 0."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="noise realisations")
    parser.add_argument("--order", type=int, default=6)
    args = parser.parse_args(argv)
    lin = build_model(load_scene(SCENE)).linearized()
    variants = (("okid-era", False), ("okid-eradc", False), ("okid-eradc", True))
    rows = []
    for seed in range(args.seeds):
        rec = hammer_test(lin, seed)
        for method, combined in variants:
            ident = identify(rec.u, rec.y, rec.dt, method, args.order, combined=combined,
                             refine=False)
            name = method + (" combined" if combined else "")
            for f, z in zip(ident.modes.frequency_hz, ident.modes.damping_ratio, strict=True):
                k = int(np.argmin(np.abs(rec.frequency_hz - f)))
                f0, z0 = rec.frequency_hz[k], rec.damping_ratio[k]
                rows.append([seed, name, f"{f0:.4f}", f"{f:.4f}", f"{100 * (f / f0 - 1):+.3f}",
                             f"{z0:.5f}", f"{z:.5f}", f"{100 * (z / z0 - 1):+.1f}"])
    print(format_table(["seed", "method", "f_model Hz", "f_id Hz", "df %", "zeta_model",
                        "zeta_id", "dzeta %"], rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
