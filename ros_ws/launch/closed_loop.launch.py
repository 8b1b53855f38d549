"""ROS 2 launch file: sim_node, estimator_node and controller_node in the /frame namespace.

    ros2 launch ros_ws/launch/closed_loop.launch.py [scene:=/abs/path/scene.yaml] [mode:=realtime]

Parameters come from ``ros_ws/config/closed_loop.params.yaml``; the ``scene`` and ``mode`` launch
arguments override the file's values. Needs a sourced ROS 2 (Jazzy) with the workspace built
(``colcon build`` in ``ros_ws/``; see docs/launch.md). Without ROS 2, ``stillframe launch SCENE``
does the same.
"""

from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

WORKSPACE = Path(__file__).resolve().parents[1]
PARAMS = WORKSPACE / "config" / "closed_loop.params.yaml"
DEFAULT_SCENE = WORKSPACE.parent / "scenes" / "thesis_lqg.yaml"
NODES = ("sim_node", "estimator_node", "controller_node")


def generate_launch_description() -> LaunchDescription:
    arguments = [
        DeclareLaunchArgument("scene", default_value=str(DEFAULT_SCENE),
                              description="scene file (YAML)"),
        DeclareLaunchArgument("mode", default_value="lockstep",
                              description="lockstep | realtime"),
    ]
    overrides = {"scene": LaunchConfiguration("scene"), "mode": LaunchConfiguration("mode")}
    nodes = [
        Node(package=name, executable=name, name=name, namespace="frame", output="screen",
             parameters=[str(PARAMS), overrides])
        for name in NODES
    ]
    return LaunchDescription([*arguments, *nodes])
