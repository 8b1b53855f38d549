"""``stillframe bench scaling``'s bookkeeping (no wall-clock asserts): the rows' ratios and
shares against their own figures, the plants' sizes against the models, bad input."""

from __future__ import annotations

import json

import pytest

from stillframe.app.bench.scaling import PLANTS, SCENE, overrides
from stillframe.config.scene import load_scene
from stillframe.plant.frame_plant import make_plant
from tests.support.middleware import run_stillframe


def test_one_process_rows_are_consistent_ratios_of_one_run() -> None:
    done = run_stillframe("bench", "scaling", "--no-nodes", "--duration", "1", "--json",
                          timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = json.loads(done.stdout)["rows"]
    assert [r["plant"] for r in rows] == [label for label, _ in PLANTS]
    first = rows[0]["one_process_us"]
    for row, (_, plant) in zip(rows, PLANTS, strict=True):
        assert row["steps"] == 32 and row["substeps"] == 32      # 1 s at 32 Hz, dt = 1/1024 s
        assert row["one_process_over_first"] == pytest.approx(row["one_process_us"] / first)
        assert row["plant_share"] == pytest.approx(row["plant_us"] / row["one_process_us"])
        assert "nodes_us" not in row
        scene = load_scene(SCENE, overrides(plant, 1.0))
        assert row["states"] == 2 * make_plant(scene).model.n_dof
    # the FE mesh grows with the elements per column
    sizes = {r["plant"]: r["states"] for r in rows}
    assert sizes["FE 3"] < sizes["FE 10"] < sizes["FE 40"]
    assert sizes["modal 3"] < sizes["modal 12"]


def test_a_short_duration_is_refused() -> None:
    done = run_stillframe("bench", "scaling", "--duration", "0.5", timeout=120)
    assert done.returncode == 2
    assert "--duration must be >= 1 s" in done.stderr
