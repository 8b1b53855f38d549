"""MKR: physical mass, stiffness and damping matrices from an identified state-space model
(thesis §3.7, eqs. 3.214–3.242).

Conditions (checked, :class:`InputError` otherwise):

- the model order is ``2 n_dof`` and every eigenvalue is complex (all modes underdamped);
- every degree of freedom carries a sensor or an actuator (the DOFs are ``0 .. n_dof - 1``, with
  ``n_dof`` the number of distinct instrumented DOFs), each sensor and each actuator acts on one
  DOF (Boolean ``C_s`` and ``B_2``), and at least one sensor–actuator pair is co-located;
- all sensors measure the same kind of quantity: displacement (b = 0), velocity (b = 1) or
  acceleration (b = 2), eq. 3.228;
- inputs are the physical forces at the actuated DOFs (the unit of B_2 sets the scale of M, K, R).

The result is expressed in the DOF order ``0 .. n_dof - 1``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stillframe.errors import IdentificationError, InputError
from stillframe.identification.modal import continuous_eigenvalues

Array = NDArray[np.float64]

OUTPUT_POWERS = {"displacement": 0, "velocity": 1, "acceleration": 2}
IMAGINARY_TOLERANCE = 1e-6
"""Largest relative imaginary part of M, K, R tolerated before refusing (eqs. 3.239–3.241)."""


@dataclass(frozen=True)
class PhysicalModel:
    """``M x'' + R x' + K x = B_2 u`` identified from a state-space model (eq. 3.1)."""

    M: Array
    K: Array
    R: Array


def continuous_model(A: Array, B: Array, dt: float) -> tuple[Array, Array]:
    """``A_c = ln(A) / dt`` (eq. 3.58 on the spectrum) and ``B_c = (A - I)^-1 A_c B`` (eq. 3.43)."""
    lam, psi = np.linalg.eig(A)
    lam_c = continuous_eigenvalues(lam, dt)
    a_c = psi @ np.diag(lam_c) @ np.linalg.inv(psi)
    if np.max(np.abs(a_c.imag)) > IMAGINARY_TOLERANCE * max(np.max(np.abs(a_c.real)), 1.0):
        raise IdentificationError(
            "the discrete model has negative real eigenvalues: no continuous model")
    a_c = a_c.real
    b_c = np.linalg.solve(A - np.eye(A.shape[0]), a_c @ B)
    return a_c, b_c


def _check_layout(sensor_dofs: Sequence[int], actuator_dofs: Sequence[int], order: int,
                  m: int, r: int) -> int:
    if len(sensor_dofs) != m:
        raise InputError(f"{len(sensor_dofs)} sensor DOFs given for a model with {m} outputs")
    if len(actuator_dofs) != r:
        raise InputError(f"{len(actuator_dofs)} actuator DOFs given for a model with {r} inputs")
    if len(set(sensor_dofs)) != m:
        raise InputError("MKR needs one sensor per DOF at most (two sensors share a DOF)")
    if len(set(actuator_dofs)) != r:
        raise InputError("MKR needs one actuator per DOF at most (two actuators share a DOF)")
    dofs = set(sensor_dofs) | set(actuator_dofs)
    n_dof = len(dofs)
    if dofs != set(range(n_dof)):
        raise InputError(f"sensor and actuator DOFs must number the DOFs 0..{n_dof - 1}, "
                         f"got {sorted(dofs)}")
    if order != 2 * n_dof:
        raise InputError(
            f"MKR needs every DOF instrumented: model order {order} means {order // 2} DOFs but "
            f"sensors and actuators cover {n_dof}"
        )
    if not set(sensor_dofs) & set(actuator_dofs):
        raise InputError("MKR needs at least one co-located sensor-actuator pair")
    return n_dof


def mass_diagnosis(mass: Array, lam: NDArray[np.complex128], t2: NDArray[np.complex128]) -> str:
    """Why MKR's mass matrix is not positive definite, from what it shows (one line).

    All eigenvalues negative: the inputs have the opposite sign to the outputs (a force measured
    with the opposite sign negates M, K and R; eq. 3.236's T_j² then all change sign). Some
    negative: at least one identified mode's co-located residue (T_j², eq. 3.236) has the sign
    no passive structure gives, i.e. the identified modes are not those of a mechanical system
    seen from the co-located pair: typically modes fitted to noise (too little signal against
    the noise) or a mode of something else in the record.
    """
    eig = np.linalg.eigvalsh(mass)
    if np.all(eig < 0):
        return ("MKR gave a negative definite mass matrix: the inputs have the opposite sign to "
                "the outputs (a force measured with the opposite sign negates M, K and R)")
    half = lam.size // 2
    majority = np.sign(np.median(t2[:half].real))
    odd = [k for k in range(half) if np.sign(t2[k].real) != majority]
    freqs = np.abs(lam[:half]) / (2 * np.pi)
    named = ", ".join(f"{freqs[k]:.4g} Hz" for k in odd) or "none alone"
    return (f"MKR gave a mass matrix with {int(np.sum(eig <= 0))} of {eig.size} eigenvalues not "
            f"positive: the identified modes are not a mechanical system seen from the "
            f"co-located sensor and actuator (modes whose co-located residue has the wrong sign: "
            f"{named}); such modes are usually fitted to noise: too little signal against the "
            f"noise, or a mode of something other than the structure")


def mkr(A: Array, B: Array, C: Array, dt: float, sensor_dofs: Sequence[int],
        actuator_dofs: Sequence[int], output: str = "acceleration") -> PhysicalModel:
    """M, K, R from the discrete model ``(A, B, C)`` sampled at ``dt`` (eqs. 3.232–3.241).

    ``sensor_dofs[i]`` is the DOF measured by output i, ``actuator_dofs[j]`` the DOF driven by
    input j; ``output`` is ``displacement``, ``velocity`` or ``acceleration``.
    """
    if output not in OUTPUT_POWERS:
        raise InputError(f"unknown output type {output!r}; choose one of "
                         f"{', '.join(OUTPUT_POWERS)}")
    A, B, C = (np.asarray(x, dtype=float) for x in (A, B, C))
    order = A.shape[0]
    m, r = C.shape[0], B.shape[1]
    sensor_dofs = [int(d) for d in sensor_dofs]
    actuator_dofs = [int(d) for d in actuator_dofs]
    n_dof = _check_layout(sensor_dofs, actuator_dofs, order, m, r)
    b = OUTPUT_POWERS[output]
    a_c, b_c = continuous_model(A, B, dt)
    lam, psi = np.linalg.eig(a_c)
    upper = lam.imag > 1e-9 * np.abs(lam)
    if 2 * np.count_nonzero(upper) != order:
        raise IdentificationError(
            "MKR needs all modes underdamped, but the model has a real eigenvalue")
    # conjugate pairs side by side, so that W, and hence M, K, R, come out real
    lam = np.concatenate([lam[upper], lam[upper].conj()])
    psi = np.hstack([psi[:, upper], psi[:, upper].conj()])
    b_m = np.linalg.solve(psi, b_c)  # (n, r), eq. 3.206
    c_m = C @ psi  # (m, n), eq. 3.207
    sensor = {d: i for i, d in enumerate(sensor_dofs)}
    actuator = {d: j for j, d in enumerate(actuator_dofs)}
    pair = min(set(sensor) & set(actuator))
    # eq. 3.236 for the co-located pair: C_m(s, j) lambda_j^-b T_j^2 = B_m(j, a)
    t2 = b_m[:, actuator[pair]] * lam**b / c_m[sensor[pair]]
    half = order // 2
    t = np.concatenate([np.sqrt(t2[:half]), np.sqrt(t2[:half]).conj()])
    w = np.empty((n_dof, order), dtype=complex)
    for dof in range(n_dof):
        if dof in actuator:
            w[dof] = b_m[:, actuator[dof]] / t  # eq. 3.237
        else:
            w[dof] = c_m[sensor[dof]] * lam ** (-b) * t  # eq. 3.238
    mass = np.linalg.inv(w @ np.diag(lam) @ w.T)  # eq. 3.239
    stiffness = -np.linalg.inv(w @ np.diag(1.0 / lam) @ w.T)  # eq. 3.240
    damping = -mass @ w @ np.diag(lam**2) @ w.T @ mass  # eq. 3.241
    out = []
    for name, mat in (("mass", mass), ("stiffness", stiffness), ("damping", damping)):
        scale = max(np.max(np.abs(mat.real)), np.finfo(float).tiny)
        if np.max(np.abs(mat.imag)) > IMAGINARY_TOLERANCE * scale:
            raise IdentificationError(
                f"MKR gave a complex {name} matrix: the model does not satisfy its "
                             "conditions (check sensor/actuator DOFs and output type)")
        out.append(0.5 * (mat.real + mat.real.T))
    if np.any(np.linalg.eigvalsh(out[0]) <= 0):
        raise IdentificationError(mass_diagnosis(out[0], lam, t2))
    return PhysicalModel(M=out[0], K=out[1], R=out[2])
