"""Launch the ARM node graph on a full ROS 2 Jazzy install (launch/launch_ros are not installable in
this project's wheel-based environment, where scripts/bringup.py does the same job).

    ros2 launch launch/arm_pipeline.launch.py use_sim:=true
"""

import os

from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

CONFIG = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "config")


def generate_launch_description():
    use_sim = LaunchConfiguration("use_sim")
    nodes = [
        Node(
            package="arm_sim",
            executable="sim_node",
            parameters=[os.path.join(CONFIG, "sim_node.yaml")],
            condition=IfCondition(use_sim),
        ),
        Node(
            package="arm_segmentation",
            executable="segmentation_node",
            parameters=[os.path.join(CONFIG, "segmentation_node.yaml")],
        ),
        Node(
            package="arm_reconstruction",
            executable="reconstruction_node",
            parameters=[os.path.join(CONFIG, "reconstruction_node.yaml")],
        ),
        Node(package="arm_planner", executable="plan_node", parameters=[os.path.join(CONFIG, "plan_node.yaml")]),
    ]
    return LaunchDescription([DeclareLaunchArgument("use_sim", default_value="true")] + nodes)
