"""The three loop nodes keep nothing per sample: sim_node, estimator_node and controller_node in
this process on the ``dds`` backend, their samples handed over in-process (``--compose-all``'s
path) or through DDS (the three-process path: write, take, read), run lock-step for a thousand
samples with the collector off. Every container object born in that stretch and still alive at
its end is counted (``gc.get_objects(generation=0)`` after a collection at its start): what the
nodes hold between samples is replaced, not kept, so the count cannot grow with the samples."""

from __future__ import annotations

import gc
import sys

import pytest

from container_node.node import Container
from controller_node.node import ControllerNode
from estimator_node.node import EstimatorNode
from sim_node.node import SimNode
from stillframe.contract import topics
from stillframe.middleware import api, intra_process
from stillframe.node_runtime.declarations import SimParameterValues
from stillframe.node_runtime.support import LoopParameters
from tests.support.scenes import thesis_scene

#: 1280 samples at 32 Hz; counted from sample FROM to sample TO
SCENE = ["duration=40", "controller.start=3", "evaluation.window=2"]
FROM, TO = 300, 1200
#: alive at the end and born in the stretch, whatever its length: the controller's newest
#: estimate and last command, the measurement's own dict and tuples (seven were counted when
#: this was written); a container kept per sample would add at least TO - FROM
HELD = 16
#: a status period longer than any run: what is counted is per sample, never per second
NO_STATUS_S = 86400.0


@pytest.fixture
def in_process(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> bool:
    """Whether the nodes made in this test hand their samples over in-process."""
    monkeypatch.setattr(intra_process, "_enabled", bool(request.param))
    return bool(request.param)


@pytest.mark.parametrize("in_process", [True, False], ids=["in-process", "through-dds"],
                         indirect=True)
def test_a_thousand_lockstep_samples_keep_no_object(ros_domain: int, in_process: bool) -> None:
    scene = thesis_scene("thesis_lqg", SCENE)
    # no /diagnostics in the stretch: a status is due per second of wall time, so a loaded
    # machine (a slower run) would publish more of them, and what they allocate is counted
    params = LoopParameters(scene, "lockstep", NO_STATUS_S)
    nodes = [api.create_node(name, namespace=topics.DEFAULT_NAMESPACE, argv=["test"],
                             backend="dds")
             for name in ("estimator_node", "controller_node", "sim_node")]
    counted: dict[str, int] = {}
    try:
        container = Container(EstimatorNode(nodes[0], params), ControllerNode(nodes[1], params))
        sim = SimNode(nodes[2], params,
                      {SimParameterValues: SimParameterValues(discovery_timeout_s=10.0)})
        period = sim.sample_period

        def counting_period(k: int) -> object:
            if k == FROM:
                gc.collect()
                gc.disable()
                counted["blocks"] = sys.getallocatedblocks()
            elif k == TO:
                counted["objects"] = len(gc.get_objects(generation=0))
                counted["blocks"] = sys.getallocatedblocks() - counted["blocks"]
                gc.enable()
            return period(k)

        def spin(timeout_s: float) -> None:      # the container's turn, else the sim's wait
            if not container.advance():
                sim.node.spin_once(min(timeout_s, 0.001))
                container.spin(0.0)
                container.advance()
            container.housekeeping()

        sim.sample_period = counting_period
        sim.spin = spin
        container.controller.subscribe_inputs()
        container.estimator.subscribe_inputs()
        history, error = sim.run()
    finally:
        gc.enable()
        for node in reversed(nodes):
            node.destroy_node()
    assert error is None and history.evaluation["complete"]
    assert counted["objects"] <= HELD
    # and the allocator's blocks: what the interpreter's free lists keep is bounded whatever
    # the stretch; one block kept every second sample would pass this
    assert counted["blocks"] < (TO - FROM) / 2
