"""``stillframe identify`` end to end on real rosbag2 bags holding a simulated known system.

The system is a 3-DOF shear frame with the rig's masses and column stiffnesses and positive
Rayleigh damping (tests/support/identify.py); its force and floor accelerations are written on
the topic contract's topics. Reference values: the continuous eigenvalues of that model (ZOH
sampling maps them exactly to the discrete poles, so noise-free data must give them to rounding).
"""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin

from stillframe.app.cli import main
from stillframe.errors import BagError, IdentificationError
from stillframe.identification.model_file import load_model
from stillframe.locations import REPO_ROOT
from tests.support.identify import (
    FORCE_TOPIC,
    IMU_TOPICS,
    frame_matrices,
    simulate,
    true_modes,
    write_frame_bag,
)

ROOT = REPO_ROOT
DT = 1 / 32
SAMPLES = 2048
CHANNELS = ["--input", f"{FORCE_TOPIC}:wrench.force.x",
            "--output", IMU_TOPICS[0], "--output", IMU_TOPICS[1],
            "--output", f"{IMU_TOPICS[2]}:linear_acceleration.x"]


def stillframe(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stillframe", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def noisy_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2 % sensor noise (of each output's RMS), MCAP, as the simulator would record it."""
    force, acc = simulate(SAMPLES, DT, seed=1, noise=0.02)
    return write_frame_bag(tmp_path_factory.mktemp("bags") / "noisy", force, acc, DT)


@pytest.fixture(scope="module")
def clean_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Noise-free, sqlite3 storage (the other rosbag2 backend)."""
    force, acc = simulate(SAMPLES, DT, seed=2)
    return write_frame_bag(tmp_path_factory.mktemp("bags") / "clean", force, acc, DT,
                           storage=StoragePlugin.SQLITE3)


def identify_json(bag: Path, *extra: str) -> dict:
    result = stillframe("identify", str(bag), *CHANNELS, "--json", *extra)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def test_noise_free_bag_gives_the_exact_modes(clean_bag: Path) -> None:
    doc = identify_json(clean_bag, "--order", "6", "--method", "okid-era")
    freq, zeta = true_modes()
    got_f = np.array([m["frequency_hz"] for m in doc["modes"]])
    got_z = np.array([m["damping_ratio"] for m in doc["modes"]])
    np.testing.assert_allclose(got_f, freq, rtol=1e-6)
    np.testing.assert_allclose(got_z, zeta, rtol=1e-4)


@pytest.mark.parametrize(("options", "damping_tol"), [
    (("--method", "okid-era"), 0.1),
    (("--method", "okid-eradc"), 0.1),
    (("--method", "okid-eradc", "--combined"), 0.25),
])
def test_noisy_bag_recovers_frequencies(noisy_bag: Path, options: tuple[str, ...],
                                        damping_tol: float) -> None:
    """2 % noise: frequencies within 0.5 %, damping ratios within 10 % (the issue's hammer-test
    tolerances); the combined [Y, Y0] realization's damping is the weaker estimate (measured
    15 % off on the first mode before the records were normalised, 20.6 % since), so it gets
    25 %."""
    doc = identify_json(noisy_bag, "--order", "6", *options)
    freq, zeta = true_modes()
    got_f = np.array([m["frequency_hz"] for m in doc["modes"]])
    got_z = np.array([m["damping_ratio"] for m in doc["modes"]])
    np.testing.assert_allclose(got_f, freq, rtol=5e-3)
    np.testing.assert_allclose(got_z, zeta, rtol=damping_tol)


def test_decimated_record_keeps_the_modes(tmp_path: Path) -> None:
    """Recorded at 64 Hz, decimated by 2 to 32 Hz (all modes below 8.9 Hz stay well inside the
    new band): same tolerances as at 32 Hz, and dt doubles."""
    force, acc = simulate(2 * SAMPLES, DT / 2, seed=7, noise=0.02)
    bag = write_frame_bag(tmp_path / "fast", force, acc, DT / 2)
    doc = identify_json(bag, "--order", "6", "--decimate", "2", "--detrend")
    assert doc["dt"] == pytest.approx(DT, rel=1e-9)
    freq, zeta = true_modes()
    np.testing.assert_allclose([m["frequency_hz"] for m in doc["modes"]], freq, rtol=5e-3)
    np.testing.assert_allclose([m["damping_ratio"] for m in doc["modes"]], zeta, rtol=0.1)


def test_lowpassed_record_keeps_the_modes(noisy_bag: Path) -> None:
    """A 12 Hz zero-phase low-pass on input and output alike leaves the 2-8.9 Hz modes; the band
    it empties needs a smaller observer order (docs/identification-tool.md)."""
    doc = identify_json(noisy_bag, "--order", "6", "--lowpass", "12", "--observer-order", "6")
    np.testing.assert_allclose([m["frequency_hz"] for m in doc["modes"]], true_modes()[0],
                               rtol=5e-3)


# ERA/DC's modes are checked by default in test_noisy_bag_recovers_frequencies
@pytest.mark.parametrize("method", ["okid-era", pytest.param("okid-eradc", marks=pytest.mark.long)])
def test_json_schema_and_auto_order(noisy_bag: Path, method: str) -> None:
    doc = identify_json(noisy_bag, "--order", "auto", "--method", method)
    assert {"order", "dt", "modes", "hankel_singular_values", "method"} <= doc.keys()
    assert doc["method"] == method
    assert doc["dt"] == pytest.approx(DT, rel=1e-9)
    assert doc["order"] == 6  # three modes: the largest Hankel singular-value gap
    assert doc["order_selection"]["gap"] > 10
    s = np.array(doc["hankel_singular_values"])
    assert np.all(np.diff(s) <= 0) and s[-1] >= 0
    assert doc["order_selection"]["gap"] == pytest.approx(s[5] / s[6], rel=1e-9)
    assert doc["warnings"] == []
    assert set(doc["refinement"]) == {"noise_model", "converged", "stop", "iterations",
                                      "evaluations", "covariance", "identifiable_parameters"}
    # white sensor noise on a measured input: the output-error model's errors are white
    assert doc["refinement"]["noise_model"] == "output-error"
    freqs = [m["frequency_hz"] for m in doc["modes"]]
    assert freqs == sorted(freqs) and len(freqs) == 3
    for mode in doc["modes"]:
        assert set(mode) == {"frequency_hz", "damping_ratio", "shape", "consistent",
                             "frequency_ci_hz", "damping_ci",
                             "shape_phase_ci"}  # refined by default
        assert mode["consistent"] is True  # three physical modes, clearly in the record
        shape = np.array(mode["shape"])
        assert shape.shape == (3, 2)  # [magnitude, phase_rad] per output
        assert shape[:, 0].max() == pytest.approx(1.0)  # normalised to the largest component
        assert np.all(np.abs(shape[:, 1]) <= np.pi)


def test_table_lists_the_modes(noisy_bag: Path) -> None:
    result = stillframe("identify", str(noisy_bag), *CHANNELS, "--order", "6")
    assert result.returncode == 0, result.stderr
    assert "refinement: output-error model, converged (" in result.stdout
    rows = [line.split() for line in result.stdout.splitlines() if line.strip()[:1].isdigit()]
    np.testing.assert_allclose([float(r[1]) for r in rows], true_modes()[0], rtol=5e-3)


def test_default_fields_are_the_contract_quantities(noisy_bag: Path) -> None:
    """Without FIELD, Imu means linear_acceleration.x and WrenchStamped wrench.force.x."""
    explicit = identify_json(noisy_bag, "--order", "6")
    result = stillframe("identify", str(noisy_bag), "--input", FORCE_TOPIC,
                        *[a for t in IMU_TOPICS for a in ("--output", t)], "--order", "6",
                        "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == explicit


def test_era_impulse_on_a_hammer_record(tmp_path: Path) -> None:
    """A single force pulse at the first sample (the hammer test): ERA on the pulse response."""
    force, acc = simulate(SAMPLES, DT, seed=3)
    force[:] = 0.0
    force[0] = 5.0
    from scipy import signal

    from tests.support.identify import discrete_model

    _, acc, _ = signal.dlsim((*discrete_model(DT), DT), force)
    bag = write_frame_bag(tmp_path / "hammer", force, acc, DT)
    doc = identify_json(bag, "--order", "6", "--method", "era-impulse")
    np.testing.assert_allclose([m["frequency_hz"] for m in doc["modes"]], true_modes()[0],
                               rtol=1e-6)


def test_save_model_with_mkr_recovers_m_k_r(clean_bag: Path, tmp_path: Path) -> None:
    """Noise-free data, three floor accelerometers and the force on floor 1: MKR gives the
    simulated M, K and C back; the file records provenance."""
    path = tmp_path / "model.npz"
    result = stillframe("identify", str(clean_bag), *CHANNELS, "--order", "6", "--method",
                        "okid-era", "--mkr", "0,1,2:0", "--save-model", str(path))
    assert result.returncode == 0, result.stderr
    model = load_model(path)
    M, K, C = frame_matrices()
    scale = np.abs(K).max()
    np.testing.assert_allclose(model.physical.M, M, atol=1e-5 * np.abs(M).max())
    np.testing.assert_allclose(model.physical.K, K, atol=1e-5 * scale)
    np.testing.assert_allclose(model.physical.R, C, atol=1e-4 * np.abs(C).max())
    assert model.provenance["bag"] == str(clean_bag)
    assert model.provenance["outputs"][2] == f"{IMU_TOPICS[2]}:linear_acceleration.x"
    assert model.provenance["order"] == 6 and model.provenance["method"] == "okid-era"
    assert model.provenance["rayleigh_alpha"] == pytest.approx(0.5, rel=1e-3)
    assert model.provenance["rayleigh_beta"] == pytest.approx(2e-4, rel=1e-3)


@pytest.mark.parametrize("extra", [[], ["--fast"]])
def test_plots_are_written(noisy_bag: Path, tmp_path: Path, extra: list[str]) -> None:
    """By default (refined) the stabilization diagram also carries the 95 % intervals."""
    out = tmp_path / "plots"
    result = stillframe("identify", str(noisy_bag), *CHANNELS, "--order", "6", "--plots",
                        str(out), "--progress", *extra)
    assert result.returncode == 0, result.stderr
    names = {"hankel_singular_values.png", "stabilization.png", "frf.png", "mode_shapes.png"}
    assert {p.name for p in out.iterdir()} == names
    for name in names:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert "writing plots" in result.stderr  # progress on stderr


# --- refusals: one line naming what is wrong; exit 2 for the arguments, 3 for an unreadable bag,
# 5 for data that cannot identify a model (stillframe.errors) -----------------------------------


def refuse(bag: Path, *args: str, exit_code: int = 2) -> str:
    """Run the command in this process (the same ``main`` as ``python -m stillframe``; one
    subprocess per refusal would only add interpreter start-ups)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["identify", str(bag), *args])
    assert code == exit_code, err.getvalue()
    lines = err.getvalue().strip().splitlines()
    assert len(lines) == 1, err.getvalue()
    assert lines[0].startswith("stillframe identify: error: ")
    return lines[0]


def test_refusal_through_the_process_exit_code(noisy_bag: Path) -> None:
    result = stillframe("identify", str(noisy_bag), *CHANNELS, "--output", "/frame/floor9/imu")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"stillframe identify: error: bag {noisy_bag} has no topic /frame/floor9/imu (topics: "
        f"{', '.join(sorted([FORCE_TOPIC, *IMU_TOPICS]))})"]


def test_refuses_missing_topic(noisy_bag: Path) -> None:
    msg = refuse(noisy_bag, *CHANNELS, "--output", "/frame/floor4/imu")
    assert "no topic /frame/floor4/imu" in msg


def test_refuses_missing_field(noisy_bag: Path) -> None:
    msg = refuse(noisy_bag, *CHANNELS, "--output", f"{IMU_TOPICS[0]}:linear_acceleration.w")
    assert "sensor_msgs/msg/Imu has no field 'w'" in msg


def test_refuses_non_numeric_field(noisy_bag: Path) -> None:
    msg = refuse(noisy_bag, *CHANNELS, "--output", f"{IMU_TOPICS[0]}:header.frame_id")
    assert "is not a number" in msg


def test_refuses_no_outputs(noisy_bag: Path) -> None:
    assert "--output" in refuse(noisy_bag, "--input", FORCE_TOPIC)


def test_refuses_non_uniform_sampling(tmp_path: Path) -> None:
    force, acc = simulate(512, DT, seed=4)
    shift = int(0.4 * DT * 1e9)  # sample 300 of the load cell 40 % of a step late
    bag = write_frame_bag(tmp_path / "jitter", force, acc, DT,
                          stamp_edits={FORCE_TOPIC: {300: shift}})
    msg = refuse(bag, *CHANNELS, "--order", "6", exit_code=IdentificationError.exit_code)
    assert "not uniform" in msg and FORCE_TOPIC in msg and "t = 9.34375 s" in msg


def test_refuses_gap(tmp_path: Path) -> None:
    force, acc = simulate(512, DT, seed=5)
    bag = write_frame_bag(tmp_path / "gap", force, acc, DT,
                          stamp_edits={IMU_TOPICS[1]: {100: None, 101: None, 102: None}})
    msg = refuse(bag, *CHANNELS, "--order", "6", exit_code=IdentificationError.exit_code)
    assert f"{IMU_TOPICS[1]}:linear_acceleration.x: gap of 3 samples after t = 3.09375 s" in msg


def test_refuses_record_too_short_for_order(tmp_path: Path) -> None:
    force, acc = simulate(60, DT, seed=6)
    bag = write_frame_bag(tmp_path / "short", force, acc, DT)
    msg = refuse(bag, *CHANNELS, "--order", "40", exit_code=IdentificationError.exit_code)
    assert "60 samples too short for order 40" in msg


def test_refuses_a_directory_that_is_no_bag(tmp_path: Path) -> None:
    assert "metadata.yaml: missing (not a rosbag2 directory?)" in refuse(
        tmp_path, *CHANNELS, exit_code=BagError.exit_code)


def test_all_zero_field_is_refused_by_topic_and_field(noisy_bag: Path) -> None:
    """Issue 27: the excitation's wrench.force.y is all zero; exit 5 naming topic and field."""
    msg = refuse(noisy_bag, "--input", f"{FORCE_TOPIC}:wrench.force.y", *CHANNELS[2:],
                 exit_code=IdentificationError.exit_code)
    assert f"channel {FORCE_TOPIC}:wrench.force.y is all zero" in msg


def test_fast_path_warns_that_it_is_not_refined(noisy_bag: Path) -> None:
    result = stillframe("identify", str(noisy_bag), *CHANNELS, "--order", "6", "--fast")
    assert result.returncode == 0, result.stderr
    assert "stillframe identify: warning: not refined" in result.stderr


def test_noise_model_option(noisy_bag: Path) -> None:
    """``--noise-model output-error`` keeps K = 0 and says so in the JSON; an unknown structure
    is refused by the parser (exit 2) naming the choices."""
    doc = identify_json(noisy_bag, "--order", "6", "--noise-model", "output-error")
    assert doc["refinement"]["noise_model"] == "output-error"
    result = stillframe("identify", str(noisy_bag), *CHANNELS, "--noise-model", "arx")
    assert result.returncode == 2
    assert "innovations" in result.stderr and "output-error" in result.stderr


def test_a_lone_mcap_file_gives_the_bags_result(noisy_bag: Path) -> None:
    """Issue 31 item 5: the bag's .mcap alone, as the help promises, gives the same document."""
    (mcap,) = noisy_bag.glob("*.mcap")
    assert identify_json(mcap, "--order", "6") == identify_json(noisy_bag, "--order", "6")


@pytest.mark.parametrize("scale", [1e-300, 1e300])
def test_outputs_in_any_units_give_the_same_modes(tmp_path: Path, scale: float) -> None:
    """Issue 31 item 5, issue 37: accelerations written scaled by 1e±300 into the bag give the
    same modes and intervals to 1e-9 relative: the records differ only by the rounding of the
    unit change, and the refinement converges to its optimum, whose sensitivity to that rounding
    is round-off times the Jacobian's condition (tests/integration/test_numerics_any_blas.py
    bounds it below 1e-9 on a like record)."""
    force, acc = simulate(1024, DT, seed=8, noise=0.02)
    plain = identify_json(write_frame_bag(tmp_path / "plain", force, acc, DT), "--order", "6")
    scaled = identify_json(write_frame_bag(tmp_path / "scaled", force, acc * scale, DT),
                           "--order", "6")
    assert plain["refinement"]["converged"] and scaled["refinement"]["converged"]
    assert len(scaled["modes"]) == len(plain["modes"])
    for ours, ref in zip(scaled["modes"], plain["modes"], strict=True):
        for key in ("frequency_hz", "damping_ratio", "frequency_ci_hz", "damping_ci"):
            np.testing.assert_allclose(ours[key], ref[key], rtol=1e-9, atol=0, err_msg=key)


def test_ssi_cov_is_output_only_with_intervals_and_mac(noisy_bag: Path, tmp_path: Path) -> None:
    """Issue 27 must show 6: the bag's three accelerations alone; the frame's modes within 1 %,
    each with an interval, the AutoMAC, the figures; an --input is refused."""
    outputs = CHANNELS[2:]
    result = stillframe("identify", str(noisy_bag), *outputs, "--method", "ssi-cov", "--order",
                        "6", "--json", "--plots", str(tmp_path / "p"))
    assert result.returncode == 0, result.stderr
    doc = json.loads(result.stdout)
    assert doc["method"] == "ssi-cov" and doc["order"] == 6
    np.testing.assert_allclose([m["frequency_hz"] for m in doc["modes"]], true_modes()[0],
                               rtol=1e-2)
    for mode in doc["modes"]:
        lo, hi = mode["frequency_ci_hz"]
        assert lo <= mode["frequency_hz"] <= hi
    assert np.allclose(np.diag(doc["auto_mac"]), 1.0)
    assert {p.name for p in (tmp_path / "p").iterdir()} == {
        "singular_values.png", "stabilization.png", "mode_shapes.png", "mac.png"}
    msg = refuse(noisy_bag, *CHANNELS, "--method", "ssi-cov")
    assert "output-only identification takes no --input" in msg


def test_withheld_intervals_are_said_once_not_called_wide() -> None:
    """The shipped hammer bag (256 samples): its prediction errors are correlated, so no mode gets
    an interval (None in the JSON, the reason in the warnings); a mode without an interval is not
    also listed as one whose interval is wide."""
    result = stillframe("identify", str(ROOT / "bags" / "hammer"), "--input",
                        "/frame/excitation/wrench", "--output", "/frame/floor1/imu", "--output",
                        "/frame/floor2/imu", "--output", "/frame/floor3/imu", "--order", "6",
                        "--noise-model", "output-error", "--json")
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert [m["frequency_ci_hz"] for m in document["modes"]] == [None] * 3
    assert [w for w in document["warnings"] if w.startswith("no intervals:")]
    assert not [w for w in document["warnings"] if w.startswith("uncertain modes")]
