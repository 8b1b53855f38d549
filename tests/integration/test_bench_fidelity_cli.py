"""``stillframe bench fidelity`` and ``bench speed`` through the command line (``--quick``).

Independent checks, not speed assertions: the Pareto front is recomputed here by a dominance
test; RK4 points the bench did not run lie beyond the stability limit predicted from the model's
eigenvalues (:func:`stillframe.dynamics.stability.rk4_stable_step`); an RK4 error at a step size
that did
run matches an integration by the numpy path.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from stillframe.config.scene import scene_from_dict
from stillframe.dynamics.models import build_model
from stillframe.dynamics.stability import rk4_stable_step
from tests.support.middleware import run_stillframe

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def fidelity(tmp_path_factory) -> tuple[dict, Path]:
    plots = tmp_path_factory.mktemp("plots")
    done = run_stillframe("bench", "fidelity", "--quick", "--json", "--plots", str(plots),
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout), plots


def pareto_front(points: list[dict]) -> list[tuple]:
    """Points no other point beats in both cost and error (a direct O(n²) dominance test)."""
    ran = [p for p in points if p["error"] is not None]
    front = [p for p in ran if not any(
        q["cpu_per_s"] <= p["cpu_per_s"] and q["error"] <= p["error"]
        and (q["cpu_per_s"] < p["cpu_per_s"] or q["error"] < p["error"]) for q in ran)]
    return sorted((p["model"], p["method"], p["dt"]) for p in front)


def test_the_reported_pareto_front_is_the_non_dominated_set(fidelity) -> None:
    doc, _ = fidelity
    assert set(doc["pareto"]) == {"hammer", "worst_case", "swing"}
    for scene, front in doc["pareto"].items():
        points = [p for p in doc["points"] if p["scene"] == scene]
        assert sorted((p["model"], p["method"], p["dt"]) for p in front) == pareto_front(points)
        costs = [p["cpu_per_s"] for p in front]
        errors = [p["error"] for p in front]
        assert costs == sorted(costs) and errors == sorted(errors, reverse=True)


def test_reference_is_converged_below_every_reported_error(fidelity) -> None:
    doc, _ = fidelity
    assert doc["reference"]["model"] == "fe40"
    for scene, ref in doc["reference"]["per_scene"].items():
        errors = [p["error"] for p in doc["points"] if p["scene"] == scene and p["error"]]
        assert ref["richardson_error"] < min(errors), scene


def test_rk4_points_left_out_are_exactly_those_beyond_the_predicted_limit(fidelity) -> None:
    doc, _ = fidelity
    for p in (p for p in doc["points"] if p["method"] == "rk4"):
        overrides = ["damping.model=modal", *doc["scenes"][p["scene"]]]
        model_type = p["model"].rstrip("0123456789")
        size = p["model"][len(model_type):]
        if model_type == "fe":
            overrides += ["model.type=fe", f"model.elements_per_column={size}"]
        elif model_type == "modal":
            overrides += ["model.type=modal", "model.elements_per_column=40",
                          f"model.modes={size}"]
        limit = rk4_stable_step(build_model(scene_from_dict({"name": "t"}, overrides)))
        assert (p["error"] is None) == (p["dt"] > limit), (p, limit)


def test_plots_are_written_per_scene(fidelity) -> None:
    _, plots = fidelity
    for scene in ("hammer", "worst_case", "swing"):
        png = plots / f"fidelity_{scene}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", png


def test_bench_speed_reports_ratios_of_one_run() -> None:
    done = run_stillframe("bench", "speed", "--quick", "--json", timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    doc = json.loads(done.stdout)
    rk4, fe40 = doc["lumped_rk4"], doc["fe40_midpoint_1ms"]
    assert rk4["ratio"] == pytest.approx(rk4["compiled_steps_per_s"] / rk4["numpy_steps_per_s"])
    assert fe40["ratio"] == pytest.approx(
        fe40["compiled_real_time_factor"] / fe40["numpy_real_time_factor"])
    rows = doc["implicit_step_cost"]["rows"]
    dofs = np.array([r["dofs"] for r in rows], float)
    cost = np.array([r["us_per_step"] for r in rows])
    assert doc["implicit_step_cost"]["exponent"] == pytest.approx(
        np.polyfit(np.log(dofs), np.log(cost), 1)[0])
    assert all(r["bandwidth"] <= 4 for r in rows)  # banded solves: constant half-bandwidth
    ph, fe = doc["ph"], doc["fe3_midpoint_plant"]
    assert ph["ph_over_fe_cost"] == pytest.approx(ph["us_per_step"] / fe["us_per_step"])
    assert ph["rate_1khz_real_time_factor"] == pytest.approx(1e3 / ph["rate_1khz_us_per_period"])


@pytest.mark.parametrize(("duration", "says"), [
    ("-1", "--duration: '-1': seconds must lie in (0, 1e+06]"),     # the option's own bound
    ("0.015", "--duration: must be a positive multiple of 0.01 s")])  # the output grid
def test_a_duration_off_the_output_grid_is_refused(duration: str, says: str) -> None:
    done = run_stillframe("bench", "fidelity", "--duration", duration, timeout=120)
    assert done.returncode == 2
    assert says in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_energy_drift_rows_include_the_ph_model(fidelity) -> None:
    doc, _ = fidelity
    rows = {(r["model"], r["method"]): r for r in doc["energy_drift"]}
    assert rows[("ph2", "avf-midpoint")]["energy_drift"] < 1e-12
    assert rows[("lumped", "midpoint")]["energy_drift"] > 1e-9
