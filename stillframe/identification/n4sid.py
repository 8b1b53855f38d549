"""N4SID through the ``nfoursid`` package (PO-MOESP), the second implementation that the
identification results are compared with."""

from __future__ import annotations

import numpy as np
import pandas as pd
from nfoursid.nfoursid import NFourSID

from stillframe.errors import InputError

__all__ = ["identify_n4sid"]


def identify_n4sid(u: np.ndarray, y: np.ndarray, order: int, block_rows: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A, B, C, D of order ``order`` from inputs u (N, m) and outputs y (N, p)."""
    m, p = u.shape[1], y.shape[1]
    if order > p * block_rows:
        raise InputError(f"N4SID: order {order} exceeds outputs x block rows = {p * block_rows}")
    names_u = [f"u{i}" for i in range(m)]
    names_y = [f"y{i}" for i in range(p)]
    frame = pd.DataFrame(np.hstack([u, y]), columns=names_u + names_y)
    n4 = NFourSID(frame, output_columns=names_y, input_columns=names_u,
                  num_block_rows=block_rows)
    n4.subspace_identification()
    model, _ = n4.system_identification(rank=order)
    return model.a, model.b, model.c, model.d
