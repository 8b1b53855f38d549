"""The scene's controller: ``controller.type`` on the design model (scene ``design`` section)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from stillframe.config.scene import Scene
from stillframe.contract.signals import ACTUATOR
from stillframe.control.euk import EUKLaw
from stillframe.control.limits import CommandLimits
from stillframe.control.lqg import ConditionedLQGLaw, LQGLaw, design_lqr
from stillframe.control.passivity import PassivityLaw
from stillframe.control.prediction import DelayPredictor
from stillframe.control.supervisor import Controller
from stillframe.dynamics.models import FrameModel
from stillframe.errors import InputError

if TYPE_CHECKING:
    from stillframe.control.mpc import MPCLaw

TORQUE_INPUT = 3  # index of the hinge torque in u = [f1, f2, f3, torque]



def check_sampled_injection(damping: float, period: float, inertia: float) -> None:
    """Passivity holds for the continuous law; held over a sample period T the injected damping
    k_d acts on the pendulum (inertia J) like explicit Euler, unstable once k_d T / J ≥ 2."""
    ratio = damping * period / inertia
    if ratio >= 2.0:
        raise InputError(
            f"controller.injection_damping: k_d T / J = {ratio:.3g} >= 2 destabilises the sampled "
            f"loop (T = {period:g} s, pendulum J = {inertia:.4g} kg m^2); use k_d < "
            f"{2 * inertia / period:.3g} or a higher sensors.rate_hz")


def check_solve_time(law: MPCLaw, horizon_s: float, period: float) -> None:
    """InputError naming ``controller.prediction_steps`` when the MPC's QP cannot be solved
    within the sample period on this machine (:meth:`MPCLaw.least_solve_s`: the least a
    solve takes, measured at load): every sample would miss its command, and the one-process
    loop would take that long per sample."""
    least = law.least_solve_s()
    if least > period:
        raise InputError(
            f"controller.prediction_steps: {law.grid.steps} steps over controller.horizon_s "
            f"{horizon_s:g} s ({law.grid.samples} samples each) make a QP that takes at least "
            f"{least * 1e3:.3g} ms to solve here, longer than the sample period "
            f"{period * 1e3:.3g} ms (1/sensors.rate_hz): fewer steps or a shorter horizon")


def make_controller(scene: Scene, design: FrameModel) -> Controller:
    """The controller of ``scene.controller.type`` (not ``none``)."""
    c = scene.controller
    period = 1.0 / scene.sensors.rate_hz
    floor = scene.excitation.floor
    delay = scene.actuators.delay_periods
    predictor = None
    limits = CommandLimits.of(scene)
    if c.type in ("lqg", "mpc"):
        lqr = design_lqr(design, period, c.state_weights, c.input_weight, TORQUE_INPUT, floor)
        if c.type == "mpc":
            from stillframe.control.mpc import (  # OSQP where MPC runs
                MPCLaw,
                PredictionGrid,
                iteration_limit,
            )

            grid = PredictionGrid.of(c.horizon_s, c.prediction_steps, period)
            coarse = lqr if grid.samples == 1 else design_lqr(
                design, grid.samples * period, c.state_weights, c.input_weight, TORQUE_INPUT,
                floor)
            law = MPCLaw(coarse, c.input_weight,
                         limits=limits, grid=grid, angle_index=design.phi_index,
                         rate_weight=c.rate_weight, angle_penalty=c.angle_penalty,
                         max_iter=iteration_limit(c.max_iter, period))
            check_solve_time(law, c.horizon_s, period)
        elif c.anti_windup:
            law = ConditionedLQGLaw(lqr, c.feedforward, limits, design.phi_index)
        else:
            law = LQGLaw(lqr, c.feedforward)
        if delay:
            predictor = DelayPredictor(lqr.A, lqr.B, delay, period)
    elif c.type in ("euk_pendulum", "euk_floor"):
        variant = "pendulum" if c.type == "euk_pendulum" else "floor"
        law = EUKLaw(design, variant, floor, c.hold_stiffness, c.hold_damping, c.singular_margin)
    elif c.type == "passivity":
        law = PassivityLaw(design.n_dof, design.phi_index, c.shaping_stiffness,
                           c.injection_damping)
        check_sampled_injection(c.injection_damping, period, design.pendulum_inertia)
    else:
        raise InputError(f"controller.type: {c.type!r} computes no command")
    return Controller(law, actuator=ACTUATOR[c.type], period=period, limits=limits,
                      start=c.start, watchdog_periods=c.watchdog_periods, predictor=predictor,
                      probe=probe_of(scene))


def probe_of(scene: Scene) -> np.ndarray | None:
    """The probe torque of each sample of the run (``adaptation.probe_std``; None without an
    adaptation or with a probe of 0): white, from ``adaptation.probe_seed``."""
    a = scene.adaptation
    if not a.enabled or a.probe_std == 0.0:
        return None
    samples = round(scene.duration * scene.sensors.rate_hz) + 1
    return a.probe_std * np.random.default_rng(a.probe_seed).standard_normal(samples)
