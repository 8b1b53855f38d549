"""``stillframe bench identify-hammer``: its data is the thesis's set-up and both methods'
accuracy is what the bench claims (times are printed, never asserted)."""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from stillframe.app.cli import main


@pytest.fixture(scope="module")
def bench() -> dict:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["bench", "identify-hammer", "--json", "--repeat", "1"]) == 0
    return json.loads(out.getvalue())


def test_true_modes_are_the_lumped_models(bench: dict) -> None:
    """The README's reference figures for the lumped model: 1.9846, 5.7902, 8.8248 Hz (undamped);
    the bench uses |λ| of the damped eigenvalues, which the non-proportional hinge damping moves
    by a few 1e-4."""
    assert bench["true"]["frequency_hz"] == pytest.approx([1.9846, 5.7902, 8.8248], rel=5e-4)


def test_okid_eradc_accuracy(bench: dict) -> None:
    """The issue's hammer-test tolerances: frequencies within 0.5 %, damping ratios within 10 %
    (measured on the hammer record: 0.044 % and 2.1 % at most)."""
    ours = bench["okid_eradc"]
    assert max(ours["frequency_error"]) < 5e-3
    assert max(ours["damping_error"]) < 0.1


def test_python_control_is_measured_on_the_same_data(bench: dict) -> None:
    theirs = bench["python_control"]
    assert theirs["markov_parameters"] == 256
    assert max(theirs["frequency_error"]) < 1e-2
    assert bench["time_ratio_python_control_over_ours"] == pytest.approx(
        theirs["seconds"] / bench["okid_eradc"]["seconds"])
