"""How far an identified model can be trusted: the checks behind the warnings of ``identify``.

ERA always returns a model of the requested order; at the extremes (a short record, a low
signal-to-noise ratio, an over-estimated order) some of its modes fit noise. Three checks, all
from the one Hankel factorization (thesis §3.6):

- **order gap**: σ_n / σ_{n+1} of the Hankel singular values at the chosen order (eq. 3.137's
  truncation). Below :data:`GAP_WARNING` the record does not single out this order;
- **consistency**: a mode is *consistent* when the realizations of order n + 2 and n + 4 each
  hold a mode within 1 % in frequency, 20 % in damping ratio and MAC 0.9 of it (a stabilization
  diagram read forwards from the chosen order). Modes fitted to noise move when the order grows;
- **stability**: a mode with a negative damping ratio makes the model unstable, which a passive
  structure is not.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from identification.era import HankelFactorization
from identification.modal import ModalTable, modal_parameters
from identification.stabilization import matching_modes

GAP_WARNING = 15.0
"""σ_n / σ_{n+1} below this: the chosen order is weakly supported by the record."""
CONSISTENCY_STEPS = (2, 4)
FREQUENCY_TOL, DAMPING_TOL, MAC_MIN = 0.01, 0.2, 0.9


def mode_consistency(factorization: HankelFactorization, modes: ModalTable, order: int,
                     dt: float) -> NDArray[np.bool_]:
    """Per mode of the order-``order`` realization: does it persist at orders n + 2 and n + 4?
    Orders beyond the Hankel matrix's numerical rank are skipped."""
    consistent = np.ones(len(modes), dtype=bool)
    for step in CONSISTENCY_STEPS:
        if order + step > factorization.numerical_rank:
            continue
        real = factorization.realize(order + step)
        _, close = matching_modes(modes, modal_parameters(real.A, real.C, dt),
                                  FREQUENCY_TOL, DAMPING_TOL, MAC_MIN)
        consistent &= close
    return consistent


def quality_warnings(modes: ModalTable, consistent: NDArray[np.bool_], order: int,
                     gap: float) -> list[str]:
    """One sentence per failed check; empty when the model passes all three."""
    found = []
    if np.isfinite(gap) and gap < GAP_WARNING:
        found.append(f"weak order gap: sigma_n/sigma_n+1 = {gap:.3g} at order {order} (below "
                     f"{GAP_WARNING:g}); the record does not single out this order (noise, a "
                     "short record or an over-estimated order)")
    if not consistent.all():
        listed = ", ".join(f"{f:.4g} Hz" for f in modes.frequency_hz[~consistent])
        found.append(f"inconsistent modes: {listed} change at orders {order}+2 and {order}+4 "
                     "(likely fitted to noise; the consistent ones are the physical candidates)")
    unstable = modes.damping_ratio < 0
    if unstable.any():
        listed = ", ".join(f"{f:.4g} Hz (zeta {z:.3g})" for f, z in
                           zip(modes.frequency_hz[unstable], modes.damping_ratio[unstable],
                               strict=True))
        found.append(f"unstable modes: {listed}; a passive structure has none (the record is "
                     "probably too short or too noisy)")
    return found
