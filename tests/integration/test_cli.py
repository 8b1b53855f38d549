"""The ``stillframe`` command: help, ``modes`` and ``simulate`` outputs checked against numbers."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla

from stillframe.app.commands.simulate import CSV_COLUMNS
from stillframe.config.scene import load_scene
from stillframe.dynamics.models import build_model
from stillframe.locations import REPO_ROOT

ROOT = REPO_ROOT
LUMPED = str(ROOT / "scenes" / "thesis_lumped.yaml")


def stillframe(*args: str) -> subprocess.CompletedProcess:
    result = subprocess.run([sys.executable, "-m", "stillframe", *args], cwd=ROOT,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return result


def test_help_lists_the_subcommands() -> None:
    out = stillframe("--help").stdout
    for command in ("modes", "simulate", "bench"):
        assert command in out


def test_modes_json_matches_the_schema_and_the_thesis() -> None:
    table = json.loads(stillframe("modes", LUMPED, "--json").stdout)
    assert set(table) == {"model", "dofs", "frequencies_hz", "damping_ratios", "mode_shapes"}
    assert table["model"] == "lumped" and table["dofs"] == 4
    np.testing.assert_allclose(table["frequencies_hz"], [1.0996, 1.9846, 5.7902, 8.8248],
                               rtol=1e-4)
    assert table["frequencies_hz"] == sorted(table["frequencies_hz"])
    # damping of the least damped (top) mode: Rayleigh ζ = α/2ω + βω/2 at 8.8 Hz, pendulum-coupled
    omega = 2 * np.pi * table["frequencies_hz"][3]
    assert table["damping_ratios"][3] == pytest.approx(0.9751 / (2 * omega) - 2.8815e-4 * omega / 2,
                                                       rel=0.1)
    assert [row[0] for row in table["mode_shapes"]] == [1.0] * 4


def test_modes_with_set_override_switches_model() -> None:
    table = json.loads(stillframe("modes", LUMPED, "--set", "model.type=fe", "--set",
                                  "damping.model=modal", "--set",
                                  "model.elements_per_column=40", "--json").stdout)
    assert table["dofs"] == 3 + 3 * 2 * 39 + 1
    np.testing.assert_allclose(table["frequencies_hz"][:4], [1.0995, 1.9115, 5.5743, 8.4802],
                               rtol=1e-4)


def test_simulate_steady_state_matches_the_linear_frequency_response(tmp_path: Path) -> None:
    """A small 1.9 Hz force: after the transient, the floor amplitudes equal |H(jω)| F."""
    sets = ["excitation.amplitudes=[0.05]", "excitation.frequencies_hz=[1.9]",
            "damping.model=modal", "damping.modal_ratios=[0.05, 0.05, 0.05]"]
    args = [x for s in sets for x in ("--set", s)]
    out = tmp_path / "run.npz"
    summary = json.loads(stillframe("simulate", LUMPED, *args, "--duration", "40", "--out",
                                    str(out), "--json").stdout)
    data = np.load(out)
    assert summary["steps"] == 40_000 and data["t"].size == 40_001
    last = data["t"] > 30.0
    measured = np.max(np.abs(data["floors"][last]), axis=0)
    lin = build_model(load_scene(LUMPED, sets)).linearized()
    w = 2 * np.pi * 1.9
    H = sla.solve(lin.stiffness - w**2 * lin.mass + 1j * w * lin.damping, lin.input_matrix[:, 0])
    np.testing.assert_allclose(measured, 0.05 * np.abs(H[:3]), rtol=2e-3)
    np.testing.assert_allclose(summary["peak_displacement_m"],
                               np.max(np.abs(data["floors"]), axis=0), rtol=1e-12)
    # floor accelerations are the model's, not a difference quotient: check against ẍ = -ω² x
    np.testing.assert_allclose(np.max(np.abs(data["floor_accelerations"][last]), axis=0),
                               w**2 * measured, rtol=5e-3)


def test_simulate_writes_csv_with_the_documented_columns(tmp_path: Path) -> None:
    out = tmp_path / "run.csv"
    stillframe("simulate", LUMPED, "--duration", "0.5", "--out", str(out))
    header = out.read_text().splitlines()[0].split(",")
    assert tuple(header) == CSV_COLUMNS
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    assert table.shape == (501, len(CSV_COLUMNS))
    np.testing.assert_allclose(table[:, 0], np.arange(501) * 1e-3, atol=1e-12)
    force = 0.1 * sum(np.sin(2 * np.pi * f * table[:, 0]) for f in (1.9, 5.7, 8.8))
    np.testing.assert_allclose(table[:, CSV_COLUMNS.index("excitation")], force, atol=1e-12)
