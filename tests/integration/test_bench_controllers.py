"""``stillframe bench controllers`` (issue 30, docs/controllers.md): on the torque-limited case
the anti-windup LQG and the MPC respect the limit and reduce every floor, the plain LQG does
not; the MPC does not fall back at 32 Hz and seldom at 1 kHz (iteration counts are
deterministic). Times are printed, never asserted."""

from __future__ import annotations

import json

import pytest

from stillframe.app.cli import main


@pytest.mark.slow
def test_bench_controllers_table(capsys) -> None:
    assert main(["bench", "controllers", "--quick", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    rows = {(r["case"], r["law"]): r for r in result["rows"]}
    assert {law for _, law in rows} == {"LQG", "LQG anti-windup", "MPC", "passivity", "EUK"}
    for law in ("LQG anti-windup", "MPC"):
        r = rows[("torque-limited", law)]
        assert r["violations"] == 0 and r["peak_torque"] <= 2.0
        assert min(r["reduction_pct"]) > 0 and r["max_angle"] < 3.14  # never over the top
    lqg = rows[("torque-limited", "LQG")]
    assert lqg["violations"] > 0 and lqg["max_angle"] > 3.15
    timing = {t["rate"]: t for t in result["mpc_timing"]}
    assert timing["32 Hz"]["fallbacks"] == 0
    assert set(timing) == {"32 Hz", "1 kHz"}
    # at 1 kHz the QP of the 32 Hz grid (20 steps of 32 samples): measured 2 of 4096 fall back
    assert timing["1 kHz"]["grid"] == {"steps": 20, "samples_per_step": 32}
    assert timing["1 kHz"]["samples"] == 4096
    assert timing["1 kHz"]["fallbacks"] <= 0.01 * timing["1 kHz"]["samples"]
    assert timing["1 kHz"]["peak_torque"] <= 2.0
