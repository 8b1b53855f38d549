"""The DaISy steel-subframe report: real measured data, validated on a held-out half, OKID
beside N4SID (nfoursid, a second implementation) on the same split.

Floors measured on this record (stillframe identify-daisy): mean validation fit N4SID 38.8 %,
OKID + ERA 15.1 %, OKID + ERA/DC 14.7 %, OKID + ERA refined as an output-error model 81.4 %;
the three most dominant N4SID modes (229.1, 417.5, 239.0 Hz) are found by both OKID models
within 1.2 %. The floors below sit under those values with margin for BLAS differences; an
OKID that went unstable or lost a mode would fail them.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from stillframe.locations import REPO_ROOT

ROOT = REPO_ROOT

#: one identify-daisy run (two N4SID and four OKID identifications of 4261 samples at order 20)
#: takes minutes: kept out of the default run
pytestmark = [pytest.mark.slow, pytest.mark.long]


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path]:
    plots = tmp_path_factory.mktemp("daisy")
    result = subprocess.run([sys.executable, "-m", "stillframe", "identify-daisy", "--json",
                             "--plots", str(plots)], cwd=ROOT, capture_output=True, text=True,
                            timeout=600)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout), plots


def test_split_and_outputs(report: tuple[dict, Path]) -> None:
    doc, _ = report
    assert doc["samples"] == {"identification": 4261, "validation": 4262}
    assert len(doc["outputs"]) == 4 and doc["order"] == 20


def test_validation_fit_floors(report: tuple[dict, Path]) -> None:
    methods = report[0]["methods"]
    assert methods["n4sid"]["mean_fit_percent"] > 30.0
    assert min(methods["n4sid"]["fit_percent"]) > 25.0
    assert methods["okid-era"]["mean_fit_percent"] > 10.0
    assert methods["okid-eradc"]["mean_fit_percent"] > 10.0


def test_output_error_refinement_fits_the_held_out_half_at_least_as_well_as_n4sid(
        report: tuple[dict, Path]) -> None:
    """Issue 12: OKID + ERA refined as an output-error model on the identification half reaches
    N4SID's held-out mean fit (measured 81.4 % against 38.8 %) on the same split and outputs."""
    methods = report[0]["methods"]
    assert methods["okid-era-oe"]["mean_fit_percent"] >= methods["n4sid"]["mean_fit_percent"]


def test_dominant_frequencies_agree(report: tuple[dict, Path]) -> None:
    """The three most dominant N4SID modes each have an OKID mode within 1.5 %."""
    doc, _ = report
    for method in ("okid-era", "okid-eradc"):
        rows = doc["dominant_mode_agreement"][method]
        assert len(rows) == 3
        assert max(r["relative_difference"] for r in rows) < 0.015, rows
    top = sorted(m["frequency_hz"] for m in doc["methods"]["n4sid"]["modes"][:3])
    assert top == pytest.approx([229.1, 239.0, 417.5], rel=5e-3)


def test_plots(report: tuple[dict, Path]) -> None:
    _, plots = report
    for name in ("daisy_validation.png", "daisy_modes.png"):
        data = (plots / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
