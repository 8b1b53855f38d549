"""The one-process closed loop: the thesis's tables reproduced within stated tolerances, the
determinism the three-process run relies on, and the sensor, actuator and model-file pieces."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from stillframe.contract.model_file import write_archive
from stillframe.design.identified import frame_for, identified_frame
from stillframe.dynamics.simulation import simulate
from stillframe.errors import InputError
from stillframe.loop.closed_loop import run_closed_loop
from stillframe.plant.actuators import Actuator
from stillframe.plant.frame_plant import FramePlant
from stillframe.plant.sensors import quantise
from tests.support.scenes import ROOT, lumped_scene, thesis_scene


@pytest.mark.slow
def test_lqg_reproduces_the_thesis_table() -> None:
    """Thesis eq. 5.233; one noise seed, so within 10 points of each published value."""
    scene = thesis_scene("thesis_lqg")
    red = run_closed_loop(scene).evaluation["reduction_pct"]
    for key, ref in (("displacement", scene.evaluation.reference_displacement_pct),
                     ("velocity", scene.evaluation.reference_velocity_pct)):
        assert min(red[key]) >= 50.0
        np.testing.assert_allclose(red[key], ref, atol=10.0)


@pytest.mark.slow
def test_euk_ekf_holds_floor_3_at_32_hz() -> None:
    """Thesis eq. 5.287 (93.45 % on floor 3 at dt = 1e-4 s): >= 85 % at a 31.25 ms period, and
    no floor worse than the thesis's value minus 10 points."""
    scene = thesis_scene("thesis_euk_ekf")
    evaluation = run_closed_loop(scene).evaluation
    red = evaluation["reduction_pct"]
    assert red["displacement"][2] >= 85.0
    for key, ref in (("displacement", scene.evaluation.reference_displacement_pct),
                     ("velocity", scene.evaluation.reference_velocity_pct)):
        assert np.all(np.array(red[key]) >= np.array(ref) - 10.0)
    assert evaluation["controller"]["watchdog"] == 0


def _short_lqg(overrides: list[str] | None = None):
    return thesis_scene("thesis_lqg", ["duration=6", "controller.start=3", "evaluation.window=2",
                                       *(overrides or [])])


def test_same_seeds_give_the_same_run_and_other_seeds_do_not() -> None:
    a, b = run_closed_loop(_short_lqg()), run_closed_loop(_short_lqg())
    np.testing.assert_array_equal(a.truth, b.truth)
    np.testing.assert_array_equal(a.command, b.command)
    assert a.evaluation["reduction_pct"] == b.evaluation["reduction_pct"]
    c = run_closed_loop(_short_lqg(["sensors.seed=7"]))
    assert np.max(np.abs(c.command - a.command)) > 0


def test_controller_starts_at_its_enable_time() -> None:
    history = run_closed_loop(_short_lqg())
    before = history.t < 3.0
    assert np.all(history.command[before] == 0.0)
    assert np.all(history.command[~before, 0] != 0.0)


def test_encoder_quantisation_and_sensor_noise_statistics() -> None:
    assert quantise(0.0123, 0.005) == pytest.approx(0.010)
    assert quantise(-0.0126, 0.005) == pytest.approx(-0.015)
    assert quantise(0.0123, 0.0) == 0.0123
    scene = lumped_scene(["sensors.accelerometer_noise_std=0.02", "sensors.load_cell_noise_std=0.1",
                          "sensors.accelerometer_bias=[0.5, 0, 0]", "excitation.type=none"])
    plant = FramePlant(scene)
    readings = np.array([plant.sensors.read(np.zeros(3), 0.0, 0.0)[0] for _ in range(4000)])
    forces = np.array([plant.sensors.read(np.zeros(3), 0.0, 1.0)[1] for _ in range(4000)])
    np.testing.assert_allclose(readings[:, :3].mean(axis=0), [0.5, 0, 0], atol=4 * 0.02 / 63)
    np.testing.assert_allclose(readings[:, :3].std(axis=0), 0.02, rtol=0.05)
    assert forces.mean() == pytest.approx(1.0, abs=4 * 0.1 / 63)
    assert forces.std() == pytest.approx(0.1, rel=0.05)


def test_actuator_rate_limit_and_saturation() -> None:
    a = Actuator(limit=1.0, rate_limit=10.0, period=0.01)  # 0.1 per period
    assert [a.apply(5.0) for _ in range(3)] == pytest.approx([0.1, 0.2, 0.3])
    b = Actuator(limit=1.0, rate_limit=None, period=0.01)
    assert b.apply(-3.0) == -1.0 and b.apply(0.5) == 0.5 and b.limited == 1


def test_thesis_mkr_file_is_the_printed_model() -> None:
    """Damping = α̂M̂ + β̂K̂ (eq. 5.180 from 5.176–5.178, to the printed rounding); the plant and
    design model are eq. 5.200–5.205."""
    scene = thesis_scene("thesis_lqg")
    lin = identified_frame("thesis_mkr", scene.rig, "plant.file").linearized()
    M, K, R = lin.mass[:3, :3].copy(), lin.stiffness[:3, :3], lin.damping[:3, :3]
    p = scene.rig.pendulum
    M[2, 2] -= p.mass
    np.testing.assert_allclose(R, 0.9751 * M - 2.8815e-4 * K, atol=6e-4)
    assert lin.mass[2, 3] == pytest.approx(p.mass * p.half_length)
    assert lin.mass[3, 3] == pytest.approx(p.mass * p.half_length**2 + p.inertia)
    assert lin.stiffness[3, 3] == pytest.approx(p.mass * scene.rig.gravity * p.half_length)
    assert lin.damping[3, 3] == p.hinge_damping


@pytest.mark.processes
@pytest.mark.slow
def test_command_prints_json_and_rejects_bad_input() -> None:
    run = [sys.executable, "-m", "stillframe", "closed-loop", str(ROOT / "scenes/thesis_lqg.yaml"),
           "--set", "duration=4", "--set", "controller.start=2", "--set", "evaluation.window=2"]
    out = subprocess.run([*run, "--json"], cwd=ROOT, capture_output=True, text=True, check=True)
    doc = json.loads(out.stdout)
    assert set(doc["reduction_pct"]) == {"displacement", "velocity"}
    assert doc["steps"] == 128 and doc["peak_command"] > 0
    bad = subprocess.run([*run, "--set", "integrator.dt=1e-3"], cwd=ROOT, capture_output=True,
                         text=True)
    assert bad.returncode == 2 and "integrator.dt" in bad.stderr and "Traceback" not in bad.stderr
    wrong = subprocess.run([*run, "--set", "evaluation.window=30"], cwd=ROOT,
                           capture_output=True, text=True)
    assert wrong.returncode == 2 and "evaluation.window" in wrong.stderr


def test_lumped_design_of_an_fe_scene_is_the_lumped_model() -> None:
    fe = lumped_scene(["model.type=fe", "damping.model=modal"])
    lumped = frame_for("lumped", "", fe, "design.file")
    assert lumped.n_dof == 4 and frame_for("scene", "", fe, "design.file").n_dof > 4
    np.testing.assert_allclose(lumped.linearized().stiffness,
                               frame_for("scene", "", lumped_scene(), "x").linearized().stiffness)


def test_time_varying_filter_gives_the_stationary_loop_once_converged() -> None:
    kf = run_closed_loop(_short_lqg())
    tv = run_closed_loop(_short_lqg(["estimator.type=tvkf"]))
    late = kf.t > 4.0
    scale = np.abs(kf.command[late, 0]).max()
    assert np.max(np.abs(tv.command[late, 0] - kf.command[late, 0])) < 1e-3 * scale


def test_pendulum_variant_stays_bounded_through_the_thesis_span() -> None:
    history = run_closed_loop(thesis_scene("thesis_euk_pendulum"))
    assert np.all(np.isfinite(history.truth))
    assert np.max(np.abs(history.command[:, 0])) <= 2.0
    assert history.evaluation["reduction_pct"]["displacement"][2] > 40.0


def test_identified_npz_file_loads_like_the_bundled_yaml(tmp_path) -> None:
    """An identified-model file (the one format of stillframe.contract.model_file) with MKR
    matrices gives the same structure; a file missing the state-space part is refused."""
    scene = thesis_scene("thesis_lqg")
    bundled = identified_frame("thesis_mkr", scene.rig, "plant.file").structure
    path = tmp_path / "model.npz"
    modes = {"mode_frequency_hz": np.array([1.0, 2.0, 3.0]),
             "mode_damping_ratio": np.full(3, 0.01), "mode_eigenvalue": np.full(3, -0.1 + 6j),
             "mode_shape": np.ones((3, 3), dtype=complex)}
    write_archive(path, {"A": 0.5 * np.eye(6), "B": np.zeros((6, 1)), "C": np.zeros((3, 6)),
                         "D": np.zeros((3, 1)), **modes, "M": bundled.mass,
                         "K": bundled.stiffness, "R": bundled.damping},
                  {"dt": 1 / 32, "inputs": ["u"], "outputs": ["y1", "y2", "y3"],
                   "provenance": {"method": "test", "order": 6}})
    loaded = identified_frame(str(path), scene.rig, "plant.file").structure
    np.testing.assert_array_equal(loaded.mass, bundled.mass)
    np.testing.assert_array_equal(loaded.damping, bundled.damping)
    np.savez(path, M=bundled.mass, K=bundled.stiffness, R=bundled.damping,
             meta=np.array(json.dumps({"format": "stillframe-identified-model", "version": 1})))
    with pytest.raises(InputError, match=r"missing arrays \['A', 'B', 'C', 'D'"):
        identified_frame(str(path), scene.rig, "plant.file")


@pytest.mark.parametrize(("overrides", "key"), [
    (["controller.type=lqg"], "estimator.type"),
    (["controller.type=lqg", "estimator.type=ekf"], "estimator.type"),
    (["plant.model=file", "plant.file=no_such_model"], "plant.file"),
    (["sensors.rate_hz=30", "controller.type=euk_floor", "estimator.type=truth"],
     "integrator.dt"),
    (["actuators.torque_limit=-1"], "actuators.torque_limit"),
])
def test_bad_loop_sections_name_their_key(overrides: list[str], key: str) -> None:
    with pytest.raises(InputError, match=key):
        FramePlant(lumped_scene(["duration=30", "controller.start=15", *overrides]))


@pytest.mark.slow
def test_euk_floor_full_state_holds_floor_3() -> None:
    """Variant 2 with the true state at 32 Hz: the thesis shows floor 3 held still (plots only);
    >= 95 % on floor 3 and >= 80 % elsewhere (measured 96.8 / 87–91 %)."""
    red = run_closed_loop(thesis_scene("thesis_euk_floor")).evaluation["reduction_pct"]
    assert red["displacement"][2] >= 95.0 and red["velocity"][2] >= 90.0
    assert min(red["displacement"][:2] + red["velocity"][:2]) >= 80.0


def test_open_loop_baseline_is_the_uncontrolled_simulation() -> None:
    """evaluation.baseline: open_loop takes the uncontrolled peaks from a run without control;
    without noise that run is the foundation's open-loop ``simulate`` of the same scene."""
    scene = lumped_scene(["duration=6", "controller.type=euk_floor", "estimator.type=truth",
                          "controller.start=3", "evaluation.window=2",
                          "evaluation.baseline=open_loop", "initial.floors=[1e-3, 0, 0]",
                          "controller.hold_stiffness=400", "controller.hold_damping=40"])
    evaluation = run_closed_loop(scene).evaluation
    reference = simulate(scene)
    last = reference.t >= 4.0 - 1e-9
    np.testing.assert_allclose(evaluation["peak_uncontrolled"]["displacement"],
                               np.abs(reference.floors[last]).max(axis=0), rtol=1e-10)
    np.testing.assert_allclose(evaluation["peak_uncontrolled"]["velocity"],
                               np.abs(reference.floor_velocities[last]).max(axis=0), rtol=1e-10)
    assert evaluation["reduction_pct"]["displacement"][2] > 90.0
