"""container_node: the loop's nodes in one process, as a ROS 2 component container with
intra-process communication (``stillframe launch --compose`` / ``--compose-all``, docs/nodes.md).

- ``python -m container_node.node --ros-args ...``: estimator_node and controller_node;
- ``python -m container_node.node all --ros-args ...``: sim_node too (``--compose-all``).

Every node keeps its name, parameters, ``/diagnostics`` and topics, and everything is still
published for the recorder and the monitor. Between the nodes of the container the samples are
handed over as they are written (:mod:`stillframe.middleware.intra_process`, the ``dds``
backend): the same CDR bytes, read by the same readers, so a composed run gives the
three-process numbers bit for bit. With the simulator composed, one sample is one chain of
calls in one thread: the sim publishes, the estimator estimates, the controller commands, and
the command is in when the sim looks for it; nothing waits on DDS unless a sample is missing.
"""

from __future__ import annotations

import sys

from controller_node.node import ControllerNode
from estimator_node.node import EstimatorNode
from sim_node import node as sim_node
from stillframe.contract import topics
from stillframe.middleware import api, intra_process
from stillframe.node_runtime.base import Cycle, Managed
from stillframe.node_runtime.support import wait_for_peers

#: longest wait of one spin of the estimator's node [s]: the controller's messages (the load
#: cell it matches) are taken at least this often
SPIN_S = 0.001
#: with the simulator composed, the watchdog and ``/diagnostics`` run when the sim may wait at
#: least this long [s]: time for the two status messages, with room to spare
HOUSEKEEPING_S = 0.0005


class Container(Cycle):
    """The estimator and the controller of one process, stepped together (the node runtime's
    cycle over both)."""

    def __init__(self, estimator: EstimatorNode, controller: ControllerNode) -> None:
        self.estimator = estimator
        self.controller = controller

    def process_ready(self) -> int:
        """What :meth:`advance` handled: the estimates and commands made."""
        return self.advance()

    def next_wait(self) -> float:
        """The longest wait of the next spin [s]: :data:`SPIN_S` (:meth:`spin` shortens it to the
        estimator's own wait)."""
        return SPIN_S

    def advance(self) -> int:
        """Estimate and command whatever is ready (an estimate reaches the controller as it is
        published); how many estimates and commands were made."""
        return self.estimator.process_ready() + self.controller.process_ready()

    def spin(self, timeout_sec: float) -> None:
        """Take the nodes' messages, waiting on the estimator's for at most ``timeout_sec``."""
        self.estimator.node.spin_once(min(timeout_sec, self.estimator.next_wait()))
        self.controller.node.spin_once(0.0)

    def housekeeping(self) -> bool:
        """Both nodes' housekeeping (the controller's watchdog, the graph reads until the first
        sample, ``/diagnostics`` when due); whether a status was published."""
        published = [node.housekeeping() for node in (self.estimator, self.controller)]
        return any(published)

    def finish(self) -> None:
        """Both nodes' last status and phase log, the estimator's first."""
        self.estimator.finish()
        self.controller.finish()

    def start(self) -> None:
        """Wait for the simulator in lock-step, then take the inputs."""
        if self.controller.params.lockstep:
            wait_for_peers(self.controller.node, self.controller.peers_ready)
        self.controller.subscribe_inputs()
        if self.controller.params.lockstep:
            wait_for_peers(self.estimator.node, self.estimator.peers_ready)
        self.estimator.subscribe_inputs()


def run_with_sim(sim: sim_node.SimNode, container: Container) -> None:
    """The simulator's loop drives the container: each time the sim waits (for a command, or
    for the next sample in real time), the estimator and controller first handle what it
    published; the sim's own wait for messages from outside is taken only when they did
    nothing (a sample incomplete, a command from another process). The housekeeping runs when
    the wait leaves time for it, and a wait after it is the sim's to recompute."""

    def spin(timeout_sec: float) -> None:
        if container.advance():
            if sim.pacer.lockstep:              # no deadline to keep: the status when due
                container.housekeeping()
            return
        # never late for the next sample because of it; after it the sim recomputes its wait
        if timeout_sec >= HOUSEKEEPING_S and container.housekeeping():
            return
        sim.node.spin_once(min(timeout_sec, SPIN_S))
        container.spin(0.0)
        container.advance()

    container.controller.subscribe_inputs()
    container.estimator.subscribe_inputs()
    sim.spin = spin
    sim_node.run(sim)
    container.finish()


@api.node_main
def main() -> int:
    """Run the nodes (``python -m container_node.node [all] --ros-args ...``, the parameters of
    all of them); bad parameters exit 2 with one line."""
    with_sim = "all" in sys.argv[1:sys.argv.index("--ros-args") if "--ros-args" in sys.argv
                                  else None]
    intra_process.enable()
    ns = topics.DEFAULT_NAMESPACE
    pair = [api.create_node(cls.NAME, namespace=ns, managed=True)
            for cls in (EstimatorNode, ControllerNode)]
    nodes = [*pair, *([api.create_node("sim_node", namespace=ns)] if with_sim else [])]
    try:
        # managed nodes, brought up here: configure, activate (their lifecycle services serve
        # later transitions, e.g. a deactivated controller commanding zero)
        estimator, controller = (
            Managed(cls, node, realtime=False).bring_up()
            for cls, node in zip((EstimatorNode, ControllerNode), pair, strict=True))
        container = Container(estimator, controller)  # type: ignore[arg-type]
        if with_sim:
            run_with_sim(sim_node.build(nodes[2]), container)
        else:
            container.run()
    finally:
        for node in reversed(nodes):
            node.destroy_node()
    return 0


if __name__ == "__main__":
    sys.exit(main())
