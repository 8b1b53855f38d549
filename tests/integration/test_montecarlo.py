"""Monte Carlo studies (stillframe montecarlo, docs/montecarlo.md): --vary parsing and draws,
run-by-run reproducibility (--only), the same table from an external Dask cluster of separate
processes, and failed runs recorded without stopping the study."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from stillframe.app.cli import main
from stillframe.config.scene import load_scene
from stillframe.errors import InputError
from stillframe.locations import SCENES_DIR
from stillframe.loop.parts import check_loop
from stillframe.studies.cluster import local_processes
from stillframe.studies.montecarlo import is_timing, plan
from stillframe.studies.vary import Variation, combinations, draw, parse_vary

SCENE = str(SCENES_DIR / "lqg_mismatch.yaml")
SHORT = ["--set", "duration=2", "--set", "controller.start=1", "--set", "evaluation.window=1"]
STUDY = [SCENE, *SHORT, "--vary", "rig.floor_masses=±10%", "--runs", "6", "--seed", "7"]
NOMINAL_MASSES = [1.281, 0.814, 1.380]


def test_vary_parsing():
    assert parse_vary("rig.floor_masses=±10%") == Variation("rig.floor_masses", "uniform", 0.1)
    assert parse_vary("rig.gravity=uniform:±2.5%") == Variation("rig.gravity", "uniform", 0.025)
    assert parse_vary("rig.gravity=normal:5%") == Variation("rig.gravity", "normal", 0.05)
    grid = parse_vary("sensors.rate_hz=grid:16:32:5")
    assert grid.kind == "grid" and grid.values == (16.0, 20.0, 24.0, 28.0, 32.0)
    listed = parse_vary("model.type=lumped,fe")
    assert listed.kind == "list" and listed.values == ("lumped", "fe")
    assert parse_vary("sensors.seed=1, 2,3").values == (1, 2, 3)
    for bad in ("rig.gravity", "=±10%", "rig.gravity=±ten%", "rig.gravity=grid:1:2",
                "rig.gravity=grid:1:2:0", "rig.gravity=cauchy:5%", "rig.gravity=normal:-5%"):
        with pytest.raises(InputError, match="--vary"):
            parse_vary(bad)


def test_grids_run_through_their_cartesian_product():
    a, b = parse_vary("x=1,2"), parse_vary("y=grid:0:1:3")
    assert combinations([a, b]) == [(1, 0.0), (1, 0.5), (1, 1.0), (2, 0.0), (2, 0.5), (2, 1.0)]
    rng = np.random.default_rng(0)
    picked = [draw([a, b], {}, i, rng) for i in range(8)]
    assert picked[4] == {"x": 2, "y": 0.5} and picked[7] == {"x": 1, "y": 0.5}


def test_relative_spreads_have_the_stated_distribution():
    """Each element independently: uniform ±10 % has std 0.2/√12, normal:5 % std 0.05."""
    rng = np.random.default_rng(1)
    uniform, normal = parse_vary("m=±10%"), parse_vary("m=normal:5%")
    u = np.array([draw([uniform], {"m": NOMINAL_MASSES}, i, rng)["m"] for i in range(4000)])
    factors = u / NOMINAL_MASSES
    assert factors.min() >= 0.9 and factors.max() <= 1.1
    np.testing.assert_allclose(factors.std(axis=0), 0.2 / np.sqrt(12), rtol=0.05)
    assert np.max(np.abs(np.corrcoef(factors.T) - np.eye(3))) < 0.06  # independent elements
    g = np.array([draw([normal], {"m": 9.81}, i, rng)["m"] for i in range(4000)]) / 9.81
    assert abs(g.mean() - 1.0) < 0.005 and abs(g.std() - 0.05) < 0.003


def test_run_values_reach_the_scene_and_differ_per_run():
    scene = load_scene(SCENE)
    study = plan(scene, [], [parse_vary("rig.floor_masses=±10%")], seed=3, what="closed-loop")
    first, again, other = study.spec(5), study.spec(5), study.spec(6)
    assert first == again and first.values != other.values
    loaded = load_scene(SCENE, list(first.overrides))
    assert list(loaded.rig.floor_masses) == first.values["rig.floor_masses"]
    assert loaded.sensors.seed != load_scene(SCENE, list(other.overrides)).sensors.seed
    with pytest.raises(InputError, match="numeric"):
        plan(scene, [], [parse_vary("model.type=±10%")], 0, "closed-loop")
    with pytest.raises(InputError, match="no such key"):
        plan(scene, [], [parse_vary("rig.mass=±10%")], 0, "closed-loop")
    # a listed value a node would refuse (the loop's parts built, as launch builds them)
    with pytest.raises(InputError, match=r"--vary design\.file: the value '/nonexistent\.yaml'"):
        plan(scene, [], [parse_vary("design.file=thesis_mkr,/nonexistent.yaml")], 0,
             "closed-loop")


def _study(capsys, out: Path, *extra: str) -> tuple[dict, list[dict]]:
    assert main(["montecarlo", *STUDY, "--out", str(out), "--json", *extra]) == 0
    document = json.loads(capsys.readouterr().out)
    with (out / "runs.csv").open() as handle:
        return document, list(csv.DictReader(handle))


def _without_timing(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if not is_timing(k)} for r in rows]




def test_only_reproduces_a_run_bit_for_bit_and_the_external_cluster_gives_the_same_table(
        tmp_path, capsys):
    document, rows = _study(capsys, tmp_path / "local", "--workers", "2")
    assert document["runs"] == 6 and document["failed"] == 0 and len(rows) == 6
    assert set(document["quantiles"]) == {f"reduction_pct.{q}.{f}" for q in
                                          ("displacement", "velocity") for f in (1, 2, 3)}
    d1 = [float(r["reduction_pct.displacement.1"]) for r in rows]
    q = document["quantiles"]["reduction_pct.displacement.1"]
    assert q["q50"] == pytest.approx(float(np.median(d1)), abs=1e-12)
    assert q["worst"] == min(d1) and rows[q["worst_run"]]["reduction_pct.displacement.1"] \
        == repr(min(d1))
    masses = np.array([[float(r[f"rig.floor_masses.{i}"]) for i in (1, 2, 3)] for r in rows])
    assert np.all(np.abs(masses / NOMINAL_MASSES - 1) <= 0.1) and len(np.unique(masses)) == 18
    assert (tmp_path / "local" / "histograms.png").stat().st_size > 0
    for run_id in (0, 4):
        assert main(["montecarlo", *STUDY, "--only", str(run_id), "--json"]) == 0
        one = json.loads(capsys.readouterr().out)
        alone = {k: repr(v) if isinstance(v, float) else str(v) for k, v in one.items()
                 if not is_timing(k)}
        assert alone == _without_timing([rows[run_id]])[0]
    with local_processes(2) as address:
        external, external_rows = _study(capsys, tmp_path / "external", "--scheduler", address)
    assert external["workers"] == 2 and external["scheduler"] == address
    assert _without_timing(external_rows) == _without_timing(rows)
    assert external["quantiles"] == document["quantiles"]


def test_a_failing_run_is_recorded_and_the_others_finish(tmp_path, capsys):
    """Young's modulus drawn ±50 %: a draw some 10 % above the nominal makes a valid scene whose
    model a run refuses (the thesis's Rayleigh damping gives a structural mode a negative damping
    ratio). Listed values are checked before any run; drawn ones cannot be, so each such run is
    recorded as failed with its reason and the others finish. Each run's status is the one the
    loop's own check (:func:`stillframe.loop.parts.check_loop`) gives its drawn value."""
    out = tmp_path / "fail"
    assert main(["montecarlo", SCENE, *SHORT, "--vary", "rig.columns.youngs_modulus=uniform:±50%",
                 "--runs", "6", "--seed", "3", "--workers", "1", "--out", str(out),
                 "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    with (out / "runs.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    expected = []
    for row in rows:
        sets = [*SHORT[1::2], f"rig.columns.youngs_modulus={row['rig.columns.youngs_modulus']}"]
        try:
            check_loop(load_scene(SCENE, sets))
            expected.append("ok")
        except InputError:
            expected.append("failed")
    assert [r["status"] for r in rows] == expected
    failed = [r["run"] for r, status in zip(rows, expected, strict=True) if status == "failed"]
    assert failed and len(failed) < len(rows)      # the seed draws both kinds
    assert all("negative damping ratio" in r["error"] for r in rows if r["run"] in failed)
    assert document["runs"] == 6 and document["failed"] == len(failed)
    assert document["fractions"]["failed"] == pytest.approx(len(failed) / 6)
    assert set(document["errors"]) == set(failed)
    assert all(r["reduction_pct.displacement.1"] for r in rows if r["status"] == "ok")


def test_bad_study_input_is_one_line_exit_2(capsys):
    assert main(["montecarlo", SCENE, "--vary", "rig.floor_masses=±ten%"]) == 2
    with pytest.raises(SystemExit) as usage:     # a usage error: argparse exits 2
        main(["montecarlo", SCENE, "--runs", "0"])
    assert usage.value.code == 2
    assert main(["montecarlo", SCENE, "--scheduler", "localhost:1"]) == 2
    assert main(["montecarlo", SCENE, "--runs", "3", "--only", "3"]) == 2
    assert main(["montecarlo", SCENE, "--target", "displacement>50"]) == 2
    assert main(["montecarlo", SCENE, "--seed", "-1"]) == 2
    # issue 31: a call-like distribution was split at its comma; a listed value that makes no
    # valid scene (sensors.rate_hz = 30 Hz: no whole number of 1/256 s steps) is refused
    # before any run
    assert main(["montecarlo", SCENE, "--vary", "duration=normal(1,2"]) == 2
    assert main(["montecarlo", SCENE, "--vary", "sensors.rate_hz=32,30"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 8 and all(line.startswith("stillframe montecarlo: error: ") for line in err)
    assert "normal(...) is not a distribution" in err[6]
    assert "the value 30: integrator.dt" in err[7]


@pytest.mark.long
def test_bench_sweeps_give_the_same_results_on_the_executor():
    """bench identify's cases and bench fidelity's work-precision errors, serial here and on an
    external two-worker cluster: equal (CPU times aside), to what the BLAS's thread count changes:
    this process's BLAS may use threads where the single-threaded workers do not. The errors are
    relative to the true modes, so they agree to 1e-5 of a frequency and 1e-3 of a damping ratio
    (the one-thread and two-thread BLAS differ by 7e-7 and 6e-5 on the first case here); the
    fidelity errors to 1e-9 of the output scale."""
    from stillframe.fidelity.work_precision import sweep
    from stillframe.identification.sweep import METHODS, cases, run_case
    from stillframe.studies.executor import mapper

    items = cases((40.0,), (256,), 2)
    with local_processes(2) as address:
        spread = mapper(None, address, "test")
        assert spread is not None
        identified = spread(run_case, items)
        fidelity = sweep(quick=True, duration=0.1, mapper=spread)
    for spread_case, here in zip(identified, [run_case(c) for c in items], strict=True):
        for method in METHODS:
            a, b = spread_case[method], here[method]
            assert a["missed"] == b["missed"]
            assert a["frequency_error"] == pytest.approx(b["frequency_error"], rel=0, abs=1e-5)
            assert a["damping_error"] == pytest.approx(b["damping_error"], rel=0, abs=1e-3)
    serial = sweep(quick=True, duration=0.1)

    def cases_of(result: dict) -> list:
        return [(p["scene"], p["model"], p["method"], p["dt"]) for p in result["points"]]

    assert cases_of(fidelity) == cases_of(serial) and len(cases_of(serial)) == 3 * 4 * 2 * 3
    for spread_point, here in zip(fidelity["points"], serial["points"], strict=True):
        assert (spread_point["error"] is None) == (here["error"] is None)
        if here["error"] is not None:  # the same compiled kernels; BLAS rounding aside
            assert spread_point["error"] == pytest.approx(here["error"], rel=1e-6, abs=1e-9)
    assert mapper(None, None, "test") is None


def test_an_identify_run_finds_the_models_modes():
    """--what identify, noise-free: OKID + ERA/DC recovers the eigenvalue analysis's four modes
    (modal_table) to 0.1 % in frequency and 5 % in damping."""
    from stillframe.studies.montecarlo import run_one

    scene = load_scene(str(Path(SCENE).with_name("hammer_test.yaml")), [
        "excitation.type=white_noise", "excitation.rate_hz=32", "duration=30",
        "sensors.accelerometer_noise_std=0"])
    study = plan(scene, ["sensors.seed=1"], [], seed=0, what="identify")
    figures = run_one(study.task(0))
    assert figures["modes_scored"] == 4 and figures["order"] == 8 and figures["missed"] == 0
    assert figures["frequency_error"] < 1e-3 and figures["damping_error"] < 0.05
