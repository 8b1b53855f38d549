"""Scene sections of the closed loop: plant, sensors, actuators, design model, estimator,
controller and evaluation (README "Scenes"; thesis §5.6–5.7 set-ups in ``scenes/thesis_*``).

Vectors of eight values follow the physical state [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇]; vectors of
four the measurements [a1, a2, a3, φ].
"""

from __future__ import annotations

from typing import Any

from stillframe.config.schema import Field, Section, in_range, non_negative, positive
from stillframe.errors import InputError

THESIS_STATE_WEIGHTS = [1e2, 1e2, 1e2, 1e-2, 1e2, 1e2, 1e2, 1e-2]  # Q_z, eq. 5.229


def _limit(doc: str) -> Field:
    return Field(float, None, positive, doc=doc, nullable=True)


LOOP_SCHEMA: dict[str, Any] = {
    "plant": {
        "model": Field(str, "scene", choices=("scene", "file"), doc=(
            "scene: the nonlinear model of the model section; file: the linear second-order "
            "model (identified structure + linearised pendulum) of plant.file")),
        "file": Field(str, "thesis_mkr", doc="identified model: a bundled name or a path"),
        "process_noise_std": Field("floats", [0.0] * 8, non_negative, length=8, doc=(
            "std of the increments added to the physical state once per sample (eq. 5.215)")),
        "seed": Field(int, 0, doc="process-noise random seed"),
    },
    "sensors": {
        "rate_hz": Field(float, 32.0, positive, doc="sample rate = control rate [Hz]"),
        "accelerometer_noise_std": Field(float, 0.0, non_negative, doc="[m/s^2]"),
        "accelerometer_bias": Field("floats", [0.0, 0.0, 0.0], length=3, doc="[m/s^2]"),
        "encoder_resolution": Field(float, 0.0, non_negative, doc="angle step [rad], 0: exact"),
        "encoder_noise_std": Field(float, 0.0, non_negative, doc="[rad], before quantisation"),
        "load_cell_noise_std": Field(float, 0.0, non_negative, doc="[N]"),
        "seed": Field(int, 1, doc="sensor-noise random seed"),
    },
    "actuators": {
        "torque_limit": _limit("pendulum torque saturation [N m]"),
        "torque_rate_limit": _limit("pendulum torque slew limit [N m/s]"),
        "force_limit": _limit("floor-3 force saturation [N]"),
        "force_rate_limit": _limit("floor-3 force slew limit [N/s]"),
    },
    "design": {
        "model": Field(str, "scene", choices=("scene", "lumped", "file"), doc=(
            "model of the estimator and controller: the scene's model, the lumped model of the "
            "scene's rig, or the identified structure of design.file with the rig's pendulum "
            "(eq. 5.200–5.205)")),
        "file": Field(str, "thesis_mkr", doc="identified model: a bundled name or a path"),
    },
    "estimator": {
        "type": Field(str, "none", choices=("none", "truth", "kf", "tvkf", "ekf"), doc=(
            "truth: the controller sees the true state; kf: steady-state Kalman filter; "
            "tvkf: time-varying Kalman filter; ekf: extended Kalman filter (nonlinear model)")),
        "process_noise_std": Field("floats", [1e-3] * 8, non_negative, length=8,
                                   doc="W0, per sample (eq. 5.221)"),
        "measurement_noise_std": Field("floats", [1e-3] * 4, positive, length=4,
                                       doc="V0 of [a1, a2, a3, phi] (eq. 5.222)"),
        "initial_offset": Field("floats", [0.0] * 8, length=8,
                                doc="mean initial estimate minus the true initial state (5.219)"),
        "initial_std": Field("floats", [1e-4] * 4 + [1e-5] * 4, positive, length=8,
                             doc="square roots of the initial covariance diagonal (5.220)"),
        "max_substep": Field(float, 5e-3, positive, doc="EKF: longest RK4 prediction step [s]"),
    },
    "controller": {
        "type": Field(str, "none", choices=("none", "lqg", "euk_pendulum", "euk_floor",
                                            "passivity")),
        "start": Field(float, 0.0, non_negative, doc="enable time [s]"),
        "state_weights": Field("floats", THESIS_STATE_WEIGHTS, non_negative, length=8,
                               doc="LQG: diagonal of Q_z (eq. 5.229)"),
        "input_weight": Field(float, 1e-4, positive, doc="LQG: Q_u (eq. 5.230)"),
        "feedforward": Field(bool, False, doc="LQG: feed the measured excitation force forward"),
        "hold_stiffness": Field(float, 0.0, non_negative, doc=(
            "EUK: kp [1/s^2] of the virtual constraint x3'' = -kd x3' - kp x3 (0: eq. 5.240)")),
        "hold_damping": Field(float, 0.0, non_negative, doc="EUK: kd [1/s]"),
        "shaping_stiffness": Field(float, 0.0, non_negative, doc=(
            "passivity: k_p [N m/rad] of u = -k_p phi - k_d phi' (energy shaping)")),
        "injection_damping": Field(float, 0.05, positive, doc=(
            "passivity: k_d [N m s/rad] (damping injection through the torque port)")),
        "singular_margin": Field(float, 0.02, in_range(1e-6, 1.0), doc=(
            "EUK pendulum: damping of the singularity-robust inverse, as a fraction of the "
            "gain at rest")),
        "limit": _limit("command saturation [N m or N]"),
        "watchdog_periods": Field(int, 3, positive, doc="periods without a fresh estimate"),
    },
    "evaluation": {
        "baseline": Field(str, "before_start", choices=("before_start", "open_loop"), doc=(
            "uncontrolled peaks from the window before controller.start of the same run (the "
            "thesis), or from the last window of a second run without control (same seeds)")),
        "window": Field(float, 10.0, positive, doc=(
            "steady-state peaks: max |.| over the window before controller.start (without "
            "control) and over the last window of the run (with control) [s]")),
        "reference_displacement_pct": Field("floats", [], doc=(
            "published reductions of floors 1-3 to print beside ours (thesis eq. 5.233, 5.287)")),
        "reference_velocity_pct": Field("floats", [], doc="the same for the velocities"),
    },
}


def check_loop(scene: Section) -> None:
    """Cross-field checks of the closed-loop sections (only for scenes with a controller)."""
    c, window = scene.controller, scene.evaluation.window
    if c.type == "none":
        return
    period = 1.0 / scene.sensors.rate_hz
    if period > scene.duration:
        raise InputError(f"sensors.rate_hz: one period ({period:g} s) is longer than duration")
    ratio = period / scene.integrator.dt
    if abs(ratio - round(ratio)) > 1e-6 * ratio:
        raise InputError(
            f"integrator.dt: {scene.integrator.dt:g} s does not divide the sample period "
            f"{period:g} s (1/sensors.rate_hz)"
        )
    if c.start - window < -1e-9 or c.start + window > scene.duration + 1e-9:
        raise InputError(
            f"evaluation.window: {window:g} s does not fit before controller.start ({c.start:g} s) "
            f"and after it within duration {scene.duration:g} s"
        )
    if c.type == "lqg" and scene.estimator.type == "ekf":
        raise InputError("estimator.type: LQG works on a linear model; use kf, tvkf or truth")
    if scene.estimator.type == "none":
        raise InputError(f"estimator.type: {c.type} needs a state (kf, tvkf, ekf or truth)")
