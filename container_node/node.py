"""container_node: estimator_node and controller_node in one process, as a ROS 2 component
container with intra-process communication (``stillframe launch --compose``, docs/nodes.md).

Both nodes keep their names, parameters, ``/diagnostics`` and topics: the estimates are still
published on ``state_estimate`` for the recorder and the monitor. The controller does not
subscribe to them: the estimator hands each estimate's physical state to it in-process (the
values it published, no serialisation), so a composed run gives the three-process numbers bit
for bit. One loop spins both nodes, the estimator's with its wait and the controller's without
waiting, so that neither node's messages wait for the other's timeout.
"""

from __future__ import annotations

import sys

from controller_node.node import ControllerNode
from estimator_node.node import EstimatorNode, build
from stillframe.contract import topics
from stillframe.loop.node_support import declare_loop_parameters, wait_for_peers
from stillframe.middleware import api

#: longest wait of one spin of the estimator's node [s]: the controller's messages (the load
#: cell it matches) are taken at least this often
SPIN_S = 0.001


def run(estimator: EstimatorNode, controller: ControllerNode) -> None:
    """Wait for the peers in lock-step, then estimate and control until shutdown."""
    controller.intra_process = True
    estimator.handover = controller.handed_over
    if controller.params.lockstep:
        wait_for_peers(controller.node, controller.peers_ready)
        wait_for_peers(estimator.node, estimator.peers_ready)
    controller.subscribe_inputs()
    estimator.subscribe_inputs()
    while api.ok():
        estimator.node.spin_once(min(SPIN_S, estimator.next_wait()))
        controller.node.spin_once(0.0)
        estimator.process_ready()
        controller.process_ready()
        controller.check_watchdog()
        for node in (estimator, controller):
            if node.diagnostics.due():
                node.publish_status()
    estimator.publish_status()
    controller.publish_status()


@api.node_main
def main() -> int:
    """Run both nodes (``python -m container_node.node --ros-args ...``, the parameters of
    both); bad parameters exit 2 with one line."""
    ns = topics.DEFAULT_NAMESPACE
    estimator_node = api.create_node("estimator_node", namespace=ns)
    controller_node = api.create_node("controller_node", namespace=ns)
    try:
        run(build(estimator_node),
            ControllerNode(controller_node, declare_loop_parameters(controller_node)))
    finally:
        controller_node.destroy_node()
        estimator_node.destroy_node()
    return 0


if __name__ == "__main__":
    sys.exit(main())
