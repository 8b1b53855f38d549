"""Prediction over a fixed actuation delay (``actuators.delay_periods``), against closed forms:
the predicted state equals the delayed design model run forward, and state feedback on the
prediction gives the delay-free closed loop's poles (plus d at the origin), where the same
feedback without prediction is unstable."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.control.factory import TORQUE_INPUT
from stillframe.control.lqg import design_lqr
from stillframe.control.prediction import CommandLog, DelayPredictor
from stillframe.design.identified import frame_for
from tests.support.scenes import thesis_scene

PERIOD = 1.0 / 100


def _design():
    scene = thesis_scene("thesis_lqg")
    model = frame_for("file", "thesis_mkr", scene, "design.file")
    c = scene.controller
    return design_lqr(model, PERIOD, c.state_weights, c.input_weight, TORQUE_INPUT, 1)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_the_prediction_is_the_delayed_model_run_forward(d: int) -> None:
    """x_{j+1} = A x_j + B u_{j-d}, with every command sent: x̂_{k+d|k} = x_{k+d} exactly
    (to rounding)."""
    design = _design()
    A, B = design.A, design.B[:, 0]
    rng = np.random.default_rng(4)
    u = rng.normal(size=40)
    x = [rng.normal(size=A.shape[0])]
    for j in range(39):
        x.append(A @ x[-1] + B * (u[j - d] if j >= d else 0.0))
    predictor = DelayPredictor(design.A, design.B, d, PERIOD)
    for k in range(39 - d):
        predicted = predictor.ahead(k * PERIOD, x[k])
        np.testing.assert_allclose(predicted, x[k + d], rtol=1e-10,
                                   atol=1e-12 * np.abs(x[k + d]).max())
        predictor.sent(k * PERIOD, u[k])


def closed_loop(design, d: int, predict: bool) -> np.ndarray:
    """The map of [x_k, u_{k-d}, ..., u_{k-1}] one period on, with u_k = -K x̂_{k+d|k}
    (``predict``) or u_k = -K x_k, built column by column through :class:`DelayPredictor`."""
    n = design.A.shape[0]
    columns = []
    for e in np.eye(n + d):
        x, pending = e[:n], e[n:]
        predictor = DelayPredictor(design.A, design.B, d, PERIOD)
        for j, value in enumerate(pending):       # sent for samples -d ... -1
            predictor.sent((j - d) * PERIOD, value)
        z = predictor.ahead(0.0, x) if predict else x
        u = -float(design.gain[0] @ z)
        columns.append(np.concatenate([design.A @ x + design.B[:, 0] * pending[0],
                                       pending[1:], [u]]))
    return np.array(columns).T


@pytest.mark.parametrize("d", [1, 2, 3])
def test_feedback_on_the_prediction_keeps_the_delay_free_poles(d: int) -> None:
    design = _design()
    A_cl = design.A - design.B @ design.gain
    # det(zI - M) = z^d det(zI - A_cl): the delay-free poles, and d at the origin (the pending
    # commands, flushed in d steps); compared as characteristic polynomials, which a cluster
    # of eigenvalues at 0 does not make ill-conditioned as the eigenvalues themselves are
    got = np.poly(closed_loop(design, d, predict=True))
    np.testing.assert_allclose(got, np.concatenate([np.poly(A_cl), np.zeros(d)]), atol=1e-9)
    delay_free = np.linalg.eigvals(A_cl)
    assert max(abs(delay_free)) < 1
    if d >= 2:   # without prediction, the same gain destabilises the delayed loop
        assert max(abs(np.linalg.eigvals(closed_loop(design, d, predict=False)))) > 1


def command_recursion(design, d: int, periods: int, *, report: bool) -> np.ndarray:
    """The commands u_k = −K x̂_{k+d|k} while the actuator applies zero (a safe state) and the
    structure rests at x = 0: ``report`` tells the predictor the zero actuation applied, as the
    estimate carries it; without it the predictor assumes its commands act."""
    n = design.A.shape[0]
    predictor = DelayPredictor(design.A, design.B, d, PERIOD)
    for j in range(-d - 1, 0):      # the commands in flight when the safe state began
        predictor.sent(j * PERIOD, 1.0)
    u = []
    for k in range(periods):
        z = predictor.ahead(k * PERIOD, np.zeros(n), 0.0 if report else None)
        u.append(-float(design.gain[0] @ z))
        predictor.sent(k * PERIOD, u[-1])
    return np.array(u)


@pytest.mark.parametrize("d", [1, 3, 5])
def test_commands_that_do_not_act_do_not_wind_the_prediction_up(d: int) -> None:
    """The recursion's roots (z^d + Σ K A^{i−1} B z^{d−i}) lie outside the unit circle: the
    commands the predictor assumes applied grow by that root each period. Told the actuation
    applied (zero, for a command that was not), it takes the commands in flight as zero:
    u_k = −K A^d x̂_k, here 0."""
    design = _design()
    K, A, B = design.gain[0], design.A, design.B[:, 0]
    roots = np.roots([1.0, *(K @ np.linalg.matrix_power(A, i - 1) @ B for i in range(1, d + 1))])
    growth = max(abs(roots))
    assert growth > 1
    wound = command_recursion(design, d, 200, report=False)
    assert abs(wound[-1]) > 0.1 * growth ** 150        # the recursion's growth, roughly
    np.testing.assert_array_equal(command_recursion(design, d, 200, report=True), 0.0)


def _twins(d: int, *, seed: int) -> tuple[tuple[DelayPredictor, DelayPredictor],
                                         np.random.Generator, int]:
    """Two predictors of the thesis LQG's design for delay ``d``, a generator and the state's
    size."""
    design = _design()
    pair = tuple(DelayPredictor(design.A, design.B, d, PERIOD) for _ in range(2))
    return pair, np.random.default_rng(seed), design.A.shape[0]     # type: ignore[return-value]


@pytest.mark.parametrize("report", ["sent", "held", "saturated"])
def test_a_report_other_than_the_safe_state_changes_nothing(report: str) -> None:
    """The command sent for that period applied, the one before it held (that command came
    late) or a saturated one: the commands in flight still reach the actuator, and the
    prediction is the sum over them, as without a report."""
    d = 3
    (told, untold), rng, n = _twins(d, seed=5)
    u = rng.normal(size=30)
    for k in range(30):
        x = rng.normal(size=n)
        lag = 1 + d + (report == "held")
        applied = None if k < lag else float(u[k - lag])     # None: nothing applied yet
        if report == "saturated" and applied is not None:
            applied = float(np.clip(applied, -0.5, 0.5))
        np.testing.assert_array_equal(told.ahead(k * PERIOD, x, applied),
                                      untold.ahead(k * PERIOD, x))
        for p in (told, untold):
            p.sent(k * PERIOD, u[k])


def test_an_estimate_behind_a_later_watchdog_command_predicts_over_the_commands_sent() -> None:
    """The controller's watchdog sends zero for sample 15 while the estimates of 10 – 14 are
    late; the estimate of 10 then comes. Its prediction runs over the commands sent for 5 – 9,
    as if the watchdog had not fired, not over forgotten ones read as 0."""
    (late, in_order), rng, n = _twins(5, seed=6)
    u = rng.normal(size=10)
    for k in range(10):
        for p in (late, in_order):
            p.sent(k * PERIOD, u[k])
    late.sent(15 * PERIOD, 0.0)
    x = rng.normal(size=n)
    np.testing.assert_array_equal(late.ahead(10 * PERIOD, x), in_order.ahead(10 * PERIOD, x))


def test_the_command_log_answers_as_a_scan_of_every_command_kept() -> None:
    """Commands recorded out of order, some indices twice, the old ones forgotten: each lookup
    equals the newest kept at or before it, found by scanning them all."""
    rng = np.random.default_rng(8)
    log, kept = CommandLog(), {}
    for _ in range(400):
        k = int(rng.integers(0, 200))
        log.record(k, float(k) + rng.normal())
        kept[k] = log.in_effect(k)
        if rng.random() < 0.1:
            edge = int(rng.integers(0, 200))
            older = sorted(i for i in kept if i < edge)[:-1]
            for i in older:
                del kept[i]
            log.forget_before(edge)
        j = int(rng.integers(-5, 205))
        before = [i for i in kept if i <= j]
        assert log.in_effect(j) == (kept[max(before)] if before else 0.0)
