"""The identification sweep of issue 12 (``stillframe bench identify``): its buildings, its
scoring and its summary, on small fixed cases (the full sweep is a benchmark, not a test)."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from stillframe.app.cli import main
from stillframe.identification.sweep import Case, run_case, score, shear_building


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_building_modes_are_the_eigenvalues_of_its_state_matrix(seed: int) -> None:
    """The drawn frequencies and damping ratios against numpy's eigenvalues of the first-order
    form (modal damping makes them exact: lambda = -zeta w +- i w sqrt(1 - zeta^2))."""
    b = shear_building(seed)
    n = b.M.shape[0]
    Minv = np.linalg.inv(b.M)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ b.K, -Minv @ b.C]])
    lam = np.linalg.eigvals(a)
    lam = np.sort_complex(lam[lam.imag > 0])
    wn = np.abs(lam)
    order = np.argsort(wn)
    assert 2 <= n <= 5
    assert wn[order] / (2 * np.pi) == pytest.approx(b.frequency_hz, rel=1e-9)
    assert -lam.real[order] / wn[order] == pytest.approx(b.damping_ratio, rel=1e-9)


def test_tuned_mass_buildings_have_a_closely_spaced_pair() -> None:
    """Odd seeds carry a tuned mass: the two lowest modes lie within 15 % of each other (Den
    Hartog: the split is about sqrt(mu / 2) on each side, mu <= 5 %)."""
    for seed in (1, 3, 5):
        f = shear_building(seed).frequency_hz
        assert f[1] / f[0] < 1.3


def test_score_flags_missed_and_off_modes() -> None:
    true_f, true_z = np.array([1.0, 3.0]), np.array([0.02, 0.03])
    exact = score(true_f, true_z, true_f, true_z)
    assert exact == {"frequency_error": 0.0, "damping_error": 0.0, "missed": 0, "wrong": False}
    off = score(np.array([1.02, 3.0]), true_z, true_f, true_z)
    assert off["frequency_error"] == pytest.approx(0.02) and off["wrong"]
    missed = score(np.array([3.0, 7.0]), np.array([0.03, 0.1]), true_f, true_z)
    assert missed["missed"] == 1 and missed["wrong"] and missed["frequency_error"] == np.inf
    damped = score(true_f, np.array([0.02, 0.04]), true_f, true_z)
    assert damped["damping_error"] == pytest.approx(1 / 3) and damped["wrong"]


def test_clean_case_is_identified_by_every_method() -> None:
    """60 dB, 2048 samples: N4SID and stillframe find every mode within 0.1 % in frequency."""
    result = run_case(Case(seed=2, samples=2048, snr_db=60.0))
    for method in ("stillframe", "n4sid"):
        assert result[method]["missed"] == 0
        assert result[method]["frequency_error"] < 1e-3


@pytest.mark.slow
@pytest.mark.long      # the bench sweep of every cell over its runs: a minute
def test_bench_json_cells_count_their_runs() -> None:
    """Two cells picked with --snr / --samples, two seeds each: every cell's figures are those
    of its runs (the median of two is the lower one, ``inverted_cdf``)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["bench", "identify", "--snr", "30", "--samples", "512", "256",
                     "--seeds", "2", "--json"]) == 0
    doc = json.loads(out.getvalue())
    assert len(doc["cells"]) == 2 and len(doc["runs"]) == 4
    for cell in doc["cells"]:
        runs = [r for r in doc["runs"]
                if (r["snr_db"], r["samples"]) == (cell["snr_db"], cell["samples"])]
        assert cell["snr_db"] == 30 and len(runs) == 2
        for method in ("stillframe", "stillframe_okid", "n4sid", "python_control"):
            assert cell[method]["silently_wrong"] == sum(r[method]["silently_wrong"]
                                                         for r in runs)
            assert cell[method]["frequency_error_median"] == min(r[method]["frequency_error"]
                                                                 for r in runs)
        paired = sum(r["stillframe"]["ci_covered"]["paired"] for r in runs)
        covered = sum(r["stillframe"]["ci_covered"]["frequency"] for r in runs)
        assert cell["stillframe"]["ci_coverage_frequency"] == pytest.approx(covered / paired)


def test_bench_refuses_a_cell_that_is_not_in_the_sweep() -> None:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["bench", "identify", "--snr", "25"]) == 2
    assert "--snr 25: not a cell of the sweep" in err.getvalue()
