"""The nodes' phase rings joined into sample paths (stillframe.app.bench.phases), on rings written
with times worked out by hand: each step's figures, the join by stamp (rows missing, out of
order), the worst samples explained by the step that was slow and the kernel's counters, and
the histogram against numpy's."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.app.bench import phases
from stillframe.app.bench.phases import CTL, EST, PATH, SIM, NodeRing, SamplePaths
from stillframe.node_runtime.phase_timing import COUNTERS, MARKS

US = 1_000
PERIOD = 1_000 * US
#: µs after the sample's wake-up at which each node's marks fall, in a usual sample
USUAL = {
    SIM: {"due": 0, "woke": 0, "sampled": 40, "serialized": 60, "written": 150,
          "command_in": 400, "answered": 410, "advanced": 480, "tapped": 481, "collected": 482,
          "done": 490},
    EST: {"first_in": 160, "ready": 200, "computed": 280, "serialized": 290, "written": 330,
          "collected": 335, "done": 340},
    CTL: {"estimate_in": 330, "ready": 335, "computed": 360, "serialized": 365, "written": 390,
          "collected": 395, "done": 396},
}
SLOW_SAMPLE, SLOW_US = 3, 500       # sample 3's filter step takes 500 µs more


def rings(samples: int = 6) -> dict[str, NodeRing]:
    """The three nodes' rings: sample k wakes at k periods; in sample 3 the estimator's filter
    step, and so everything after it, is 500 µs late, and the estimator's thread meets 2
    involuntary switches and 7 minor faults; the estimator has no row of sample 5, and its rows
    are kept newest first."""
    out = {}
    for node, usual in USUAL.items():
        ks = list(range(samples)) if node != EST else list(reversed(range(samples - 1)))
        columns: dict[str, np.ndarray] = {"stamp": np.array([k * PERIOD for k in ks])}
        for mark, at in usual.items():
            late = [SLOW_US if k == SLOW_SAMPLE and at > USUAL[EST]["ready"] else 0 for k in ks]
            columns[mark] = np.array([k * PERIOD + (at + d) * US
                                      for k, d in zip(ks, late, strict=True)])
        cumulative = np.cumsum([(7, 0, 0, 2) if node == EST and k == SLOW_SAMPLE else (1, 0, 1, 0)
                                for k in ks], axis=0)
        columns.update({name: cumulative[:, i] for i, name in enumerate(COUNTERS)})
        out[node] = NodeRing({"node": node, "marks": list(MARKS[node]),
                              "counters": list(COUNTERS), "sched_policy": 0}, columns)
    return out


@pytest.fixture
def paths() -> SamplePaths:
    return SamplePaths(rings())


def test_each_step_is_the_difference_of_its_marks(paths: SamplePaths) -> None:
    table = {(r["who"], r["what"]): r for r in paths.table(PATH)}
    filter_step = table[EST, "filter step"]
    # five samples have an estimator row; four took 80 µs, sample 3 took 580 µs
    assert filter_step["samples"] == 5
    assert filter_step["p50_us"] == pytest.approx(80.0)
    assert filter_step["max_us"] == pytest.approx(580.0)
    assert filter_step["mean_us"] == pytest.approx((4 * 80 + 580) / 5)
    hop = table[f"{SIM} -> {EST}", "write, wake-up, take, read the first message"]
    assert hop["p50_us"] == pytest.approx(100.0) and hop["samples"] == 5
    back = table[f"{CTL} -> {SIM}", "write, wake-up, take, read the command"]
    assert back["p50_us"] == pytest.approx(35.0)
    # the next wake-up is the next sample's: a period after this one's, less its 490 µs
    assert table[SIM, "to the next sample"]["p50_us"] == pytest.approx(1000 - 490)


def test_the_path_adds_up_to_the_sample(paths: SamplePaths) -> None:
    """In a usual sample the steps along the path cover it from wake-up to the next wake-up:
    their p50s add up to the period."""
    assert sum(r["p50_us"] for r in paths.table(PATH)) == pytest.approx(1000.0)


def test_the_worst_sample_is_explained_by_its_slow_step(paths: SamplePaths) -> None:
    latency = {k * PERIOD: 250.0 for k in range(6)}
    latency[SLOW_SAMPLE * PERIOD] = 750.0
    worst = phases.worst(latency, paths, count=2)
    assert [w["stamp"] for w in worst] == [SLOW_SAMPLE * PERIOD, 0]
    top = worst[0]
    assert top["phases"][0]["who"] == EST and top["phases"][0]["what"] == "filter step"
    assert top["phases"][0]["us"] == pytest.approx(580.0)
    assert top["phases"][0]["median_us"] == pytest.approx(80.0)
    kernel = {k["node"]: k for k in top["kernel"]}
    assert kernel[EST]["nivcsw"] == 2 and kernel[EST]["minflt"] == 7
    assert "2 involuntary context switches" in kernel[EST]["text"]
    assert worst[1]["phases"] == []
    assert "filter step 580 us (median 80)" in phases.worst_text(worst)


def test_a_sample_missing_from_a_node_is_nan_not_zero(paths: SamplePaths) -> None:
    span = paths.span_us((EST, "ready"), (EST, "computed"))
    assert np.isnan(span[5]) and span[4] == pytest.approx(80.0)


def test_a_hop_whose_end_came_first_is_not_a_hop() -> None:
    """The simulator took sample 2's command 200 µs before the controller wrote the law's (the
    watchdog's zero for that stamp came first, and the controller's ring does not time it): the
    hop is not that sample's, so it is NaN and left out of the table, not a negative time."""
    made = rings()
    made[SIM].columns["command_in"][2] = 2 * PERIOD + (USUAL[CTL]["serialized"] - 200) * US
    paths = SamplePaths(made)
    hop = paths.span_us((CTL, "serialized"), (SIM, "command_in"))
    assert np.isnan(hop[2]) and hop[1] == pytest.approx(35.0)
    row = {r["what"]: r for r in paths.table(PATH)}["write, wake-up, take, read the command"]
    assert row["samples"] == 5 and row["mean_us"] == pytest.approx(35.0)
    # within one node a mark before another is the node's own order, kept
    assert paths.span_us((SIM, "command_in"), (SIM, "answered"))[2] == pytest.approx(245.0)


def test_histogram_counts_as_numpy_does() -> None:
    rng = np.random.default_rng(3)
    latency = rng.gamma(2.0, 300.0, 5000)
    bins = phases.histogram(latency)
    edges = np.array(phases.HISTOGRAM_US, dtype=float)
    assert [b["samples"] for b in bins] == np.histogram(latency, edges)[0].tolist()
    assert sum(b["pct"] for b in bins) == pytest.approx(100.0)


def test_latency_from_the_rings_is_the_command_write_less_the_sample_write() -> None:
    """sim_node writes at 60 µs, the controller at 365 µs (865 µs in the slow sample): 305 µs
    a sample, 805 µs once, within the 1 ms period; no ring of the controller, no latency."""
    log = phases.latency_log(rings(), PERIOD)
    latency = log.latencies_us()
    assert latency == pytest.approx({k * PERIOD: 805.0 if k == SLOW_SAMPLE else 305.0
                                     for k in range(6)})
    summary = log.summary()
    assert (summary["answered"], summary["deadline_misses"]) == (6, 0)
    without = {node: ring for node, ring in rings().items() if node != CTL}
    assert phases.latency_log(without, PERIOD).latencies_us() == {}
