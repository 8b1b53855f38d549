"""Every loop node's parameters, declared once (:mod:`.parameters`); docs/nodes.md's reference
is generated from them (:data:`NODE_PARAMETERS`, :func:`.parameters.reference`):
``python -m stillframe.node_runtime.declarations`` writes it between the markers of
:data:`REFERENCE_MARKERS`."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from stillframe.contract.run_token import TOKEN_LIMITS, token_problem
from stillframe.errors import InputError
from stillframe.loop.designs import SCENE_DESIGN, design_check
from stillframe.loop.spec import (
    COMMAND_MISS_LIMIT,
    COMMAND_TIMEOUT_PERIODS,
    LOCKSTEP_TIMEOUT_S,
)
from stillframe.node_runtime.parameters import (
    FromScene,
    NodeParameters,
    at_least,
    between,
    limited,
    non_negative,
    of_length,
    param,
    positive,
    reference,
)
from stillframe.node_runtime.realtime import NO_PINNING, PRACTICES, parse_cpus, parse_practices
from stillframe.text_table import with_section


def _refusal(parse: Callable[[Any], object], name: str) -> Callable[[Any], str | None]:
    """A check from a parser that raises InputError (its text, without the parameter's name)."""
    def check(value: Any) -> str | None:
        try:
            parse(value)
        except InputError as exc:
            return str(exc).removeprefix(f"parameter '{name}': ")
        return None

    return check


def _scene_file(value: str) -> str | None:
    return None if value else "give the scene file (--ros-args -p scene:=FILE)"


_FIFO = (os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO))


@dataclass(frozen=True)
class LoopParameterValues(NodeParameters):
    """Every loop node: the scene and the loop's timing."""

    scene: str = param("", limited(_scene_file, "required"), doc=(
        "scene file (YAML, see closed-loop.md); `stillframe launch` hands the nodes the scene it "
        "resolved, with its overrides applied and `model: auto` chosen"))
    overrides: list[str] = param([""], doc=(
        "`dotted.key=value` strings applied like `--set` (empty strings are ignored: a ROS "
        "parameter cannot be an empty list), e.g. `-p 'overrides:=[\"duration=6\"]'`"))
    mode: Literal["lockstep", "realtime"] = param("lockstep", doc=(
        "lock-step (the one-process numbers, bit for bit) or real time (below)"))
    diagnostics_period_s: float = param(1.0, positive, unit="s", doc=(
        "wall time between `/diagnostics` messages"))
    run_token: str = param("", limited(token_problem, TOKEN_LIMITS), doc=(
        "the run's token: every stamped sample the node writes carries it in "
        "`header.frame_id` (`floor1#TOKEN`), and it takes only the samples that do (writer "
        "identity, below); `stillframe launch` and the launch file give each run a new one; "
        "empty: none, the `*_writer` parameters decide"))


@dataclass(frozen=True)
class RealtimeParameterValues(NodeParameters):
    """Every loop node: the real-time practices (:mod:`.realtime`)."""

    rt: str = param("", limited(_refusal(parse_practices, "rt"), "`all` or a comma list of "
                                + ", ".join(f"`{p}`" for p in PRACTICES)), doc=(
        "real-time practices (realtime.md); a practice the OS refuses is skipped with a "
        "warning; empty: none"))
    rt_priority: int = param(80, between(*_FIFO), doc="the `SCHED_FIFO` priority of `fifo`")
    rt_cpus: list[int] = param([NO_PINNING], limited(_refusal(parse_cpus, "rt_cpus"),
                                                     "CPUs of this process, or [-1]"),
                               doc="the CPUs of `affinity`; `[-1]`: no pinning")
    spin_margin_us: float = param(200.0, between(0, 10_000), unit="us", doc=(
        "with `spin`, sim_node polls instead of sleeping for this long before a due time"))


@dataclass(frozen=True)
class TimingParameterValues(NodeParameters):
    """Every loop node: the per-sample phase timing (:mod:`.phase_timing`)."""

    phase_timing: bool = param(True, doc=(
        "time the phases of every sample into a preallocated ring (a few µs a sample); false: "
        "not at all"))
    phase_log: str = param("", doc=(
        "at the end, write the ring to `<phase_log>/<node>.npz` (`stillframe bench loop` "
        "reads it); empty: kept in memory only"))


@dataclass(frozen=True)
class ManagedParameterValues(NodeParameters):
    """The managed (lifecycle) nodes: estimator_node and controller_node."""

    autostart: bool = param(True, doc=(
        "configure and activate at start (a node run by hand); `stillframe launch` sets false "
        "and brings the node through `configure` and `activate` itself, like a lifecycle-aware "
        "`ros2 launch`"))


@dataclass(frozen=True)
class SimParameterValues(NodeParameters):
    """sim_node."""

    result_file: str = param("", doc=(
        "at the end, write the evaluation as JSON here and the histories as `.npz` beside it; "
        "empty: none"))
    discovery_timeout_s: float = param(30.0, non_negative, unit="s", doc=(
        "longest wait for the estimator and controller before the first sample; after it the "
        "run starts anyway, with a warning"))
    await_recorder: list[str] = param([""], doc=(
        "topics the launch's recorder must subscribe before lock-step starts (`*`: every topic "
        "of the loop); empty: none"))
    await_status_reader: str = param("", doc=(
        "the node (fully qualified) whose `/diagnostics` reader must have matched this node's "
        "status writer before the first sample: a launch's own node, whose report takes the "
        "nodes' last statuses; empty: none"))
    command_writer: str = param("", doc=(
        "without a `run_token`: the node allowed to command (relative names in the node's "
        "namespace); empty: the first writer seen; other writers are ignored and reported"))
    lockstep_timeout_s: float = param(LOCKSTEP_TIMEOUT_S, positive, unit="s", doc=(
        "lock-step: the longest wall time one sample waits for its command while the estimator "
        "and the controller are on the graph; past it (or once one has left the graph) the run "
        "ends, incomplete, exit code 7 (the simulator never advances without the command)"))
    command_timeout_periods: int = param(COMMAND_TIMEOUT_PERIODS, at_least(1), unit="periods",
                                         doc=(
        "zero actuation (the safe state, `safe_state_samples`) once the newest command is this "
        "many periods old"))
    command_miss_limit: float = param(COMMAND_MISS_LIMIT, between(0.0, 1.0, high_open=True), doc=(
        "real time: zero actuation while more than this share of the last second's samples "
        "missed their command (`degraded_samples`); 0: never"))


#: Stamps a late input may still revise: a link's jitter of a few periods at 100 Hz, and at
#: most this many extra filter steps per spin at 1 kHz.
REFILTER_PERIODS = 5


def _half_period(scene: Any) -> float:
    return 0.5 / scene.sensors.rate_hz


@dataclass(frozen=True)
class EstimatorParameterValues(NodeParameters):
    """estimator_node (the noise parameters exist for the filters kf, tvkf and ekf)."""

    partial_after_s: float = param(FromScene("half a period", _half_period), positive,
                                   unit="s", doc=(
        "real time: how long after a stamp's first message the estimator updates with the "
        "channels that have arrived"))
    refilter_periods: int = param(REFILTER_PERIODS, at_least(0), unit="periods", doc=(
        "real time, filters without `adaptation`: an input that comes after its stamp was used "
        "without it, at most this many periods back, is taken into that stamp and the filter "
        "steps again from there (the estimates already published stay; the next ones carry it; "
        "counted in `late_inputs` and `refilters`); 0: it is dropped as stale"))
    sensor_writer: str = param("", doc=(
        "without a `run_token`: the node whose sensor samples (and `state_truth`) are taken, "
        "e.g. `sim_node`; empty: the first writer seen"))
    command_writer: str = param("", doc=(
        "as sim_node's, for the commands the estimator reads (the actuation in effect where a "
        "report was lost)"))


@dataclass(frozen=True)
class NoiseParameterValues(NodeParameters):
    """estimator_node with a filter (kf, tvkf, ekf): W0 and V0, settable while it runs."""

    process_noise_std: list[float] = param(
        FromScene("`estimator.process_noise_std`",
                  lambda s: list(s.estimator.process_noise_std)),
        of_length(8, non_negative),
        dynamic=True, doc=(
            "W0 (eq. 5.221): Q is recomputed, for `kf` the stationary covariance and gain too"))
    measurement_noise_std: list[float] = param(
        FromScene("`estimator.measurement_noise_std`",
                  lambda s: list(s.estimator.measurement_noise_std)),
        of_length(4, positive),
        dynamic=True, doc="V0 (eq. 5.222): the same recomputation with R")


@dataclass(frozen=True)
class AdaptationParameterValues(NodeParameters):
    """estimator_node with ``adaptation.enabled``: where its designs and its record go."""

    adaptation_dir: str = param("", doc=(
        "the directory the adaptation writes each design's model file into (`design_N.yaml`); "
        "empty: a new temporary directory"))
    adaptation_record: str = param("", doc=(
        "write the adaptation's updates and events as JSON here at each event and at the end; "
        "empty: none"))
    design_timeout_s: float = param(60.0, positive, unit="s", doc=(
        "the longest wait for controller_node to take or refuse a design; no answer: the "
        "design is refused, the running one stays"))


@dataclass(frozen=True)
class DesignParameterValues(NodeParameters):
    """estimator_node with a filter, and controller_node: the design they run, switched at a
    sample boundary (docs/adaptation.md)."""

    design: str = param(SCENE_DESIGN, limited(design_check, "`scene` or a model file, "
                                              "optionally `@T`"), dynamic=True, doc=(
        "the design model: `scene` (the scene's design section) or a model file (`format: "
        "stillframe-mkr` or an identified `.npz`: storeys with the rig's pendulum); `@T`: from "
        "the sample stamped T [s] on (none: the next sample). Checked when set (the model "
        "loads, the LQG designed on it has finite gains and stable poles) and refused with the "
        "reason otherwise, the running design kept; set both nodes with the same T to switch "
        "them at the same sample; `scene@T` rolls back"))


@dataclass(frozen=True)
class ControllerParameterValues(NodeParameters):
    """controller_node."""

    estimate_writer: str = param("", doc=(
        "without a `run_token`: the node whose `state_estimate` is taken, e.g. "
        "`estimator_node`; empty: the first writer seen"))
    sensor_writer: str = param("", doc=(
        "without a `run_token` (and for `/clock`, which carries none): the node whose load cell "
        "(`excitation/wrench`) and, with `use_sim_time`, `/clock` are taken, e.g. `sim_node`; "
        "empty: the first writer seen"))
    enabled: bool = param(True, dynamic=True, doc=(
        "false: the command is 0 from the next sample on (published as usual); true: the law "
        "again"))
    command_limit: float = param(
        FromScene("`controller.limit` (0 if none)", lambda s: s.controller.limit or 0.0),
        non_negative, unit="N m or N", dynamic=True, doc=(
            "the command is clipped to ±limit; 0: no limit"))


_COMMON = (LoopParameterValues, RealtimeParameterValues, TimingParameterValues)
#: the parameter declarations of each node, in the order they are declared
#: the loop's nodes by their default names (a node waits for its peers by these names, or by
#: the writer pins when set: docs/nodes.md, lock-step protocol)
LOOP_NODES = SIM, ESTIMATOR, CONTROLLER = ("sim_node", "estimator_node", "controller_node")
#: the loop's node each ``*_writer`` parameter names when it is empty: the node whose samples
#: carry the run's token on those inputs, and the peer a node waits for in lock-step
WRITER_DEFAULTS = {"command_writer": CONTROLLER, "sensor_writer": SIM,
                   "estimate_writer": ESTIMATOR}

NODE_PARAMETERS: dict[str, tuple[type[NodeParameters], ...]] = {
    SIM: (*_COMMON, SimParameterValues),
    ESTIMATOR: (*_COMMON, ManagedParameterValues, EstimatorParameterValues,
                NoiseParameterValues, DesignParameterValues, AdaptationParameterValues),
    CONTROLLER: (*_COMMON, ManagedParameterValues, ControllerParameterValues,
                 DesignParameterValues),
}

#: the lines between which docs/nodes.md holds :func:`.parameters.reference`
REFERENCE_MARKERS = ("<!-- parameter reference: generated from "
                     "stillframe/node_runtime/declarations.py -->",
                     "<!-- end of the parameter reference -->")


def with_reference(text: str) -> str:
    """``text`` (docs/nodes.md) with the reference between its markers made anew."""
    return with_section(text, REFERENCE_MARKERS, reference(NODE_PARAMETERS))


if __name__ == "__main__":
    page = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/nodes.md")
    page.write_text(with_reference(page.read_text()))
