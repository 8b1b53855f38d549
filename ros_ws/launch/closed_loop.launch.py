"""ROS 2 launch file: the closed loop in the /frame namespace, run as ``stillframe launch`` runs it.

    ros2 launch ros_ws/launch/closed_loop.launch.py [scene:=/abs/path/scene.yaml] [mode:=realtime]
                                                    [overrides:='["duration=6"]']

Parameters come from ``ros_ws/config/closed_loop.params.yaml``; the ``scene``, ``mode`` and
``overrides`` launch arguments override the file's values. Needs a sourced ROS 2 (Jazzy) with the
workspace built (``colcon build`` in ``ros_ws/``; see docs/launch.md). Without ROS 2,
``stillframe launch SCENE`` does the same.

- ``estimator_node`` and ``controller_node`` are lifecycle nodes (``LifecycleNode``), started with
  ``autostart:=false``: the launch asks each to ``configure`` (a ``ChangeState`` event) and, once
  its ``configuring`` ends in ``inactive`` (``OnStateTransition``), to ``activate``, as a
  lifecycle-aware launch does. The transitions are service calls from the launch's own rclpy
  node (Fast DDS), which do not reach nodes on the ``dds`` backend (services do not cross DDS
  vendors): with ``STILLFRAME_RMW=dds`` the two configure and activate themselves.
- Every node gets the run's token (``run_token``, drawn for each launch by
  ``stillframe/contract/run_token.py``, as ``stillframe launch`` draws it; loaded by its path,
  since this file runs in the ROS 2 installation's Python): only the samples of this launch's
  nodes reach the loop (docs/nodes.md, writer identity).
- The run ends when ``sim_node`` exits at the end of the scene (``OnProcessExit``, then a
  ``Shutdown`` event, which stops the other two with SIGINT). A simulator that exits with a failure
  code, or a managed node that exits while the run goes on, fails the launch: its exit code then
  is 1 (``ros2 launch`` gives no other), with the node's own code in the error line.
"""

import importlib.util
import os
from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, LogInfo, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown, matches_action
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from lifecycle_msgs.msg import Transition

WORKSPACE = Path(__file__).resolve().parents[1]
PARAMS = WORKSPACE / "config" / "closed_loop.params.yaml"
DEFAULT_SCENE = WORKSPACE.parent / "scenes" / "thesis_lqg.yaml"
NODES = ("sim_node", "estimator_node", "controller_node")
RUN_TOKEN = WORKSPACE.parent / "stillframe" / "contract" / "run_token.py"
SIMULATOR, MANAGED = NODES[0], NODES[1:]


def run_token_module():
    """stillframe's run-token module (standard library only), loaded from its file."""
    spec = importlib.util.spec_from_file_location("stillframe_run_token", RUN_TOKEN)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class RunFailedError(RuntimeError):
    """A node ended the run with a failure: ``ros2 launch`` logs it and exits 1."""


def end_of_scene(event, context):
    """sim_node exited: the end of the scene (code 0) shuts the launch down; anything else fails
    it."""
    if event.returncode != 0:
        raise RunFailedError(f"{SIMULATOR} exited with code {event.returncode}: the run failed")
    return [LogInfo(msg=f"{SIMULATOR} ended the scene: stopping the other nodes"),
            EmitEvent(event=Shutdown(reason=f"{SIMULATOR} ended the scene"))]


def died_during_the_run(event, context):
    """A managed node exited: after the simulator's end (the launch stops it) that is the plan;
    before, the run cannot go on."""
    if not context.is_shutdown:
        raise RunFailedError(f"{event.action.node_name} exited with code {event.returncode} while "
                        "the run went on: the run failed")


def managed(name, parameters, brought_up):
    """A lifecycle node and, when the launch ``brought_up`` it, the events that take it through
    ``configure`` and ``activate``."""
    node = LifecycleNode(package=name, executable=name, name=name, namespace="frame",
                         output="screen",
                         parameters=[*parameters, {"autostart": not brought_up}])
    if not brought_up:
        return [node]

    def change(transition):
        return EmitEvent(event=ChangeState(lifecycle_node_matcher=matches_action(node),
                                           transition_id=transition))

    return [node,
            RegisterEventHandler(OnStateTransition(
                target_lifecycle_node=node, start_state="configuring", goal_state="inactive",
                entities=[change(Transition.TRANSITION_ACTIVATE)])),
            change(Transition.TRANSITION_CONFIGURE)]


def generate_launch_description() -> LaunchDescription:
    arguments = [
        DeclareLaunchArgument("scene", default_value=str(DEFAULT_SCENE),
                              description="scene file (YAML)"),
        DeclareLaunchArgument("mode", default_value="lockstep",
                              description="lockstep | realtime"),
        DeclareLaunchArgument("overrides", default_value="['']",
                              description="dotted.key=value strings, e.g. ['duration=6']"),
    ]
    parameters = [str(PARAMS), {
        "scene": LaunchConfiguration("scene"), "mode": LaunchConfiguration("mode"),
        "overrides": LaunchConfiguration("overrides"),
        "run_token": run_token_module().new_run_token()}]
    brought_up = os.environ.get("STILLFRAME_RMW", "") != "dds"
    simulator = Node(package=SIMULATOR, executable=SIMULATOR, name=SIMULATOR, namespace="frame",
                     output="screen", parameters=parameters)
    entities = [*arguments, simulator,
                RegisterEventHandler(OnProcessExit(target_action=simulator,
                                                   on_exit=end_of_scene))]
    for name in MANAGED:
        node, *events = managed(name, parameters, brought_up)
        entities += [node, *events, RegisterEventHandler(OnProcessExit(
            target_action=node, on_exit=died_during_the_run))]
    return LaunchDescription(entities)
