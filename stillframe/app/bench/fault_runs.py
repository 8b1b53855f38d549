"""The closed loop across three hosts under network faults (``stillframe bench faults``).

One lab (:mod:`~stillframe.app.netns_lab`) for the whole bench; per fault
(:data:`~stillframe.app.net_faults.FAULTS`), with the fault on every host's incoming link:

- lock-step: the thesis LQG scene for ``duration`` s, sensor topics reliable (as lock-step
  makes them); its wall time, whether it completed and whether truth, commands and forces are
  bit-identical to the same scene in one process (``closed-loop``, computed once);
- real time at 100 Hz (``sensors.rate_hz=100``): the same scene paced by the wall clock, sensor
  topics best effort (``sensor_data``): sim_node's deadline misses, overruns, samples the
  guard held at zero and largest command, the estimate's RMS error against the truth over the
  controlled half (an observer in this process collects ``state_estimate``), estimator_node's
  partial updates and late inputs (:data:`ESTIMATOR_COUNTS`), and the displacement reductions.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from stillframe.app.bench.estimate_error import EstimateLog
from stillframe.app.bench.loop import realtime_overrides
from stillframe.app.launcher import run_scene
from stillframe.app.net_faults import Fault, applied
from stillframe.app.netns_lab import Lab, host_prefixes
from stillframe.config.scene import load_scene
from stillframe.contract.topics import DEFAULT_NAMESPACE, STATE_ESTIMATE
from stillframe.locations import SCENES_DIR
from stillframe.loop.closed_loop import LoopHistory, run_closed_loop
from stillframe.node_runtime.declarations import ESTIMATOR

SCENE = SCENES_DIR / "thesis_lqg.yaml"
RATE_HZ = 100.0
#: the histories compared bit for bit
COMPARED = ("t", "truth", "command", "force")
#: estimator_node's counts of what came late, from its last status
ESTIMATOR_COUNTS = ("partial_updates", "late_inputs", "refilters", "stale_messages")


def lockstep_overrides(duration: float) -> list[str]:
    """The LQG scene at its own rate for ``duration`` s, control from half-time."""
    return [f"duration={duration:g}", f"controller.start={duration / 2:g}",
            f"evaluation.window={duration / 2:g}"]


def identical(histories: dict[str, np.ndarray], reference: LoopHistory) -> bool:
    """Truth, commands and forces equal ``reference`` to the last bit."""
    return all(np.array_equal(histories[key], getattr(reference, key), equal_nan=True)
               for key in COMPARED)


def lockstep_row(lab: Lab, fault: Fault, duration: float, out: Path,
                 reference: LoopHistory, backends: Sequence[str],
                 overrides: Sequence[str]) -> dict[str, Any]:
    """One lock-step launch of :data:`SCENE` for ``duration`` seconds with ``fault`` applied in
    ``lab``: its steps, wall times [s], completeness, whether truth, commands and forces equal
    ``reference`` bit for bit, and the displacement reductions per floor [%]."""
    with applied(lab, fault):
        started = time.perf_counter()
        result = run_scene(SCENE, [*lockstep_overrides(duration), *overrides], out=out,
                           mode="lockstep", backends=backends,
                           hosts=host_prefixes(lab))
        launch_wall = time.perf_counter() - started
    with np.load(result.history_file) as data:
        histories = dict(data)
    e = result.evaluation
    return {"steps": e["steps"], "wall_s": e["wall_s"], "launch_wall_s": launch_wall,
            "complete": e["complete"],
            "bit_identical": identical(histories, reference),
            "reduction_pct": e["reduction_pct"]["displacement"]}


def realtime_row(lab: Lab, fault: Fault, duration: float, out: Path,
                 backends: Sequence[str], overrides: Sequence[str]) -> dict[str, Any]:
    """One real-time launch of :data:`SCENE` at :data:`RATE_HZ` for ``duration`` seconds with
    ``fault`` applied in ``lab``: its steps, deadline misses, overruns and the RMS error of the
    estimates the observer received over the second half against the truth."""
    period_ns = round(1e9 / RATE_HZ)
    log = EstimateLog(period_ns)

    def observe(node: Any) -> None:
        node.create_subscription(STATE_ESTIMATE.type_name,
                                 f"{DEFAULT_NAMESPACE}/{STATE_ESTIMATE.name}", log.on_estimate,
                                 STATE_ESTIMATE.qos)

    with applied(lab, fault):
        result = run_scene(SCENE, [*realtime_overrides(RATE_HZ, duration), *overrides],
                           out=out, mode="realtime",
                           prepare=observe, backends=backends, hosts=host_prefixes(lab))
    with np.load(result.history_file) as data:
        truth = data["truth"]
    e = result.evaluation
    error = log.rms_error(truth, from_k=round(duration / 2 * RATE_HZ))
    status = result.diagnostics.get(f"{DEFAULT_NAMESPACE}/{ESTIMATOR}", {})
    return {"steps": e["steps"], "deadline_misses": e["deadline_misses"],
            "overruns": e["overruns"], "degraded_samples": e["degraded_samples"],
            "peak_command": e["peak_command"], "estimate": error,
            "estimator": {key: int(status[key]) for key in ESTIMATOR_COUNTS if key in status},
            "reduction_pct": e["reduction_pct"]["displacement"]}


def run_bench(lab: Lab, faults: Sequence[Fault], duration: float, out: Path, *,
              modes: Sequence[str] = ("lockstep", "realtime"), backends: Sequence[str] = (),
              progress: Callable[[str], None] | None = None,
              overrides: Sequence[str] = ()) -> list[dict[str, Any]]:
    """A row per fault (module docstring), each with the fault's netem equivalent; the
    scene's ``overrides`` (``--set``) apply to every run and to the one-process reference."""
    say = progress or (lambda text: print(text, file=sys.stderr, flush=True))
    reference = (run_closed_loop(load_scene(SCENE, [*lockstep_overrides(duration), *overrides]))
                 if "lockstep" in modes else None)
    rows = []
    for i, fault in enumerate(faults):
        row: dict[str, Any] = {"fault": fault.name, "netem": fault.netem()}
        if reference is not None:
            say(f"[{i + 1}/{len(faults)}] {fault.name}: lock-step, {duration:g} s of the LQG")
            row["lockstep"] = lockstep_row(lab, fault, duration, out / f"{i}-lockstep",
                                           reference, backends, overrides)
        if "realtime" in modes:
            say(f"[{i + 1}/{len(faults)}] {fault.name}: real time at {RATE_HZ:g} Hz for "
                f"{duration:g} s")
            row["realtime"] = realtime_row(lab, fault, duration, out / f"{i}-realtime", backends,
                                           overrides)
        rows.append(row)
    return rows
