"""Scene sections of the closed loop: plant, sensors, actuators, design model, estimator,
controller and evaluation (README "Scenes"; thesis §5.6–5.7 set-ups in ``scenes/thesis_*``).

Vectors of eight values follow the physical state [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇]; vectors of
four the measurements [a1, a2, a3, φ].
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from stillframe.config.schema import (
    SEED_RANGE,
    Floats,
    Floats3,
    Floats4,
    Floats8,
    Section,
    in_range,
    key,
    magnitude,
    up_to,
)

THESIS_STATE_WEIGHTS: Floats8 = (1e2, 1e2, 1e2, 1e-2, 1e2, 1e2, 1e2, 1e-2)  # Q_z, eq. 5.229


#: the longest actuation delay, in sample periods (the LQG predicts over it; 31 s at 32 Hz)
MAX_DELAY_PERIODS = 1000
#: LQG weights within twelve decades of 1 (the Riccati solution stays finite in doubles)
MAX_WEIGHT = 1e12
#: the longest MPC prediction horizon [s] (a minute: far beyond the frame's slowest mode)
MAX_HORIZON_S = 60.0
#: the most MPC prediction steps (the QP grows with them)
MAX_PREDICTION_STEPS = 1000


#: the bound [N m or N] on a command for an actuator without a saturation limit of its own: far
#: beyond any rig's actuator, it keeps values like 1e308 from reaching the integrator. The
#: controller clips its commands to it and the simulator refuses commands beyond it
#: (:attr:`Actuators.bounds`); no saturation limit of a scene may exceed it.
COMMAND_BOUND = 1e6


def _limit(doc: str) -> Any:
    return key(None, up_to(1e12), doc=doc)


def _saturation(doc: str) -> Any:
    return key(None, up_to(COMMAND_BOUND), doc=f"{doc}; null: none (commands bounded by "
                                                 f"{COMMAND_BOUND:g})")


@dataclass(frozen=True, kw_only=True)
class Plant(Section):
    """plant: what the closed loop simulates."""

    model: Literal["scene", "file"] = key("scene", doc=(
        "scene: the nonlinear model of the model section; file: the linear second-order "
        "model (identified structure + linearised pendulum) of plant.file"))
    file: str = key("thesis_mkr", doc="identified model: a bundled name or a path")
    discretization: Literal["substeps", "zoh"] = key("substeps", doc=(
        "model file only: substeps of the scene's integrator at integrator.dt, or zoh: each "
        "substep exact for the held command and a force linear between substeps (matrix "
        "exponential)"))
    process_noise_std: Floats8 = key((0.0,) * 8, in_range(0.0, 1e6), doc=(
        "std of the increments added to the physical state once per sample (eq. 5.215)"))
    seed: int = key(0, in_range(*SEED_RANGE), doc="process-noise random seed")


@dataclass(frozen=True, kw_only=True)
class Sensors(Section):
    """sensors: the floor accelerometers, the pendulum encoder and the load cell."""

    rate_hz: float = key(32.0, up_to(1e5), doc="sample rate = control rate [Hz]")
    accelerometer_noise_std: float = key(0.0, in_range(0.0, 1e6), doc="[m/s^2]")
    accelerometer_bias: Floats3 = key((0.0, 0.0, 0.0), magnitude(1e6), doc="[m/s^2]")
    encoder_resolution: float = key(0.0, in_range(0.0, 10.0), doc="angle step [rad], 0: exact")
    encoder_noise_std: float = key(0.0, in_range(0.0, 1e3), doc="[rad], before quantisation")
    load_cell_noise_std: float = key(0.0, in_range(0.0, 1e9), doc="[N]")
    seed: int = key(1, in_range(*SEED_RANGE), doc="sensor-noise random seed")


@dataclass(frozen=True, kw_only=True)
class Actuators(Section):
    """actuators: saturation and slew limits (null: none), and a fixed actuation delay."""

    delay_periods: int = key(0, in_range(0, MAX_DELAY_PERIODS), doc=(
        "the command stamped t_k is applied from t_k+d on (a playout buffer: network delay and "
        "jitter up to d periods cost nothing more; LQG predicts d periods ahead)"))
    torque_limit: float | None = _saturation("pendulum torque saturation [N m]")
    torque_rate_limit: float | None = _limit("pendulum torque slew limit [N m/s]")
    force_limit: float | None = _saturation("floor-3 force saturation [N]")
    force_rate_limit: float | None = _limit("floor-3 force slew limit [N/s]")

    @property
    def bounds(self) -> tuple[float, float]:
        """The largest command [torque, floor-3 force] the loop passes on: each actuator's
        saturation limit, or :data:`COMMAND_BOUND` without one."""
        return (COMMAND_BOUND if self.torque_limit is None else self.torque_limit,
                COMMAND_BOUND if self.force_limit is None else self.force_limit)


@dataclass(frozen=True, kw_only=True)
class Design(Section):
    """design: the model the estimator and the controller are designed on."""

    model: Literal["scene", "lumped", "file"] = key("scene", doc=(
        "model of the estimator and controller: the scene's model, the lumped model of the "
        "scene's rig, or the identified structure of design.file with the rig's pendulum "
        "(eq. 5.200–5.205)"))
    file: str = key("thesis_mkr", doc="identified model: a bundled name or a path")
    after_events: int = key(0, in_range(0, 100), doc=(
        "scene or lumped: design on the structure after the first this many of the scene's "
        "events (0: the structure the run starts with); the oracle of an adaptation, which "
        "knows the change before it happens"))


@dataclass(frozen=True, kw_only=True)
class Estimator(Section):
    """estimator: the state estimate the controller sees."""

    type: Literal["none", "truth", "kf", "tvkf", "ekf"] = key("none", doc=(
        "truth: the controller sees the true state; kf: steady-state Kalman filter; "
        "tvkf: time-varying Kalman filter; ekf: extended Kalman filter (nonlinear model)"))
    process_noise_std: Floats8 = key((1e-3,) * 8, in_range(0.0, 1e6),
                                     doc="W0, per sample (eq. 5.221)")
    measurement_noise_std: Floats4 = key((1e-3,) * 4, up_to(1e6),
                                         doc="V0 of [a1, a2, a3, phi] (eq. 5.222)")
    initial_offset: Floats8 = key((0.0,) * 8, magnitude(1e3), doc=(
        "mean initial estimate minus the true initial state (5.219)"))
    initial_std: Floats8 = key((1e-4,) * 4 + (1e-5,) * 4, up_to(1e3),
                               doc="square roots of the initial covariance diagonal (5.220)")
    restart_velocity_std: Floats4 = key((1.0, 1.0, 1.0, 10.0), in_range(0.0, 1e6), doc=(
        "kf, tvkf started from a sample of a running loop: standard deviations of the floor "
        "velocities [m/s] and of phi' [rad/s], which one sample does not measure (the "
        "displacements and phi take the spread that the measurements and these give them)"))
    max_substep: float = key(5e-3, up_to(1.0), doc="EKF: longest RK4 prediction step [s]")


@dataclass(frozen=True, kw_only=True)
class Controller(Section):
    """controller: the control law and its supervisor."""

    type: Literal["none", "lqg", "euk_pendulum", "euk_floor", "passivity", "mpc"] = key(
        "none", doc=("mpc: linear model predictive control on the design model with the "
                     "limits of the torque, its rate and the pendulum angle (OSQP)"))
    start: float = key(0.0, in_range(0.0, 1e6), doc="enable time [s]")
    state_weights: Floats8 = key(THESIS_STATE_WEIGHTS, in_range(0.0, MAX_WEIGHT),
                                 doc="LQG: diagonal of Q_z (eq. 5.229)")
    input_weight: float = key(1e-4, in_range(1.0 / MAX_WEIGHT, MAX_WEIGHT),
                              doc="LQG: Q_u (eq. 5.230)")
    feedforward: bool = key(False, doc="LQG: feed the measured excitation force forward")
    anti_windup: bool = key(False, doc=(
        "LQG: condition the command on the actuator's limits and controller.angle_limit one "
        "period ahead on the design model (docs/controllers.md)"))
    angle_limit: float | None = key(0.5, up_to(10.0), doc=(
        "LQG anti-windup and MPC: largest pendulum angle [rad] the command may lead to (the "
        "design model's linear range; null: none); a soft constraint in MPC"))
    horizon_s: float = key(0.625, up_to(MAX_HORIZON_S), doc=(
        "MPC: prediction horizon [s], at least one sample period (20 samples at 32 Hz)"))
    prediction_steps: int = key(20, up_to(MAX_PREDICTION_STEPS), doc=(
        "MPC: most steps of the prediction grid over controller.horizon_s; each step holds the "
        "torque for a whole number of samples, so the QP does not grow with sensors.rate_hz"))
    rate_weight: float = key(0.0, in_range(0.0, MAX_WEIGHT),
                             doc="MPC: weight of the torque step (Δu)^2 per prediction step")
    angle_penalty: float = key(1e6, up_to(MAX_WEIGHT), doc=(
        "MPC: weight of the squared excess of |phi| over controller.angle_limit (and 1e-3 of "
        "it on the excess itself), relative to the weight R + B'PB of the torque's deviation "
        "from the LQR's plan"))
    max_iter: int | None = key(None, up_to(1_000_000), doc=(
        "MPC: OSQP iteration limit per sample (null: one per 5 us of the period, 50 to 4000: "
        "195 at 1024 Hz); a solve that does not finish falls back to the anti-windup LQG "
        "command (counted, in /diagnostics)"))
    hold_stiffness: float = key(0.0, in_range(0.0, 1e9), doc=(
        "EUK: kp [1/s^2] of the virtual constraint x3'' = -kd x3' - kp x3 (0: eq. 5.240)"))
    hold_damping: float = key(0.0, in_range(0.0, 1e9), doc="EUK: kd [1/s]")
    shaping_stiffness: float = key(0.0, in_range(0.0, 1e9), doc=(
        "passivity: k_p [N m/rad] of u = -k_p phi - k_d phi' (energy shaping)"))
    injection_damping: float = key(0.05, up_to(1e9), doc=(
        "passivity: k_d [N m s/rad] (damping injection through the torque port)"))
    singular_margin: float = key(0.02, in_range(1e-6, 1.0), doc=(
        "EUK pendulum: damping of the singularity-robust inverse, as a fraction of the "
        "gain at rest"))
    limit: float | None = _saturation("command saturation [N m or N]")
    watchdog_periods: int = key(3, up_to(1_000_000), doc="periods without a fresh estimate")


@dataclass(frozen=True, kw_only=True)
class Adaptation(Section):
    """adaptation: the loop notices a change of the structure, identifies it again from its own
    records and hands the controller and the estimator a new LQG design (docs/adaptation.md)."""

    enabled: bool = key(False, doc=(
        "watch the structure's frequencies, identify it again after a change and hand over a new "
        "design (LQG with a kf or tvkf estimator on the torque)"))
    probe_std: float = key(0.003, in_range(0.0, 10.0), doc=(
        "std of the white probe torque added to the command from controller.start [N m]: what "
        "makes closed-loop records identify the plant (0: none, and the identification fails)"))
    probe_seed: int = key(2, in_range(*SEED_RANGE), doc="the probe's random seed")
    detection_window: float = key(10.0, in_range(1.0, 1e4), doc=(
        "the window of records each detection update identifies [s]"))
    update_period: float = key(4.0, in_range(0.1, 1e4), doc=(
        "sample time between detection updates [s]"))
    reference_updates: int = key(8, in_range(2, 1000), doc=(
        "updates that set each mode's reference frequency and spread (after controller.start "
        "and after each hand-over)"))
    drift: float = key(2.0, in_range(0.0, 1e3), doc=(
        "CUSUM drift nu: the deviation an update may show without accumulating [reference "
        "std]"))
    threshold: float = key(40.0, in_range(1e-3, 1e6), doc=(
        "CUSUM threshold h: a change is declared once a mode's statistic exceeds it"))
    min_relative_std: float = key(1e-3, in_range(1e-6, 1.0), doc=(
        "the smallest reference spread of a mode, relative to its frequency [-]"))
    identification_window: float = key(30.0, in_range(1.0, 1e4), doc=(
        "the records after the change's estimated onset that the structure is identified "
        "from [s]"))
    handover_periods: int = key(4, in_range(1, 100_000), doc=(
        "sample periods from the end of the identification window to the hand-over: the time "
        "the identification and the design may take while the loop runs (lock-step waits for "
        "them)"))


@dataclass(frozen=True, kw_only=True)
class Evaluation(Section):
    """evaluation: peak reductions with and without control."""

    baseline: Literal["before_start", "open_loop"] = key("before_start", doc=(
        "uncontrolled peaks from the window before controller.start of the same run (the "
        "thesis), or from the last window of a second run without control (same seeds)"))
    window: float = key(10.0, up_to(1e6), doc=(
        "steady-state peaks: max |.| over the window before controller.start (without "
        "control) and over the last window of the run (with control) [s]"))
    reference_displacement_pct: Floats = key((), doc=(
        "published reductions of floors 1-3 to print beside ours (thesis eq. 5.233, 5.287)"))
    reference_velocity_pct: Floats = key((), doc="the same for the velocities")
