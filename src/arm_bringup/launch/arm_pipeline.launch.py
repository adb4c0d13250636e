"""Launch the ARM node graph on a full ROS 2 Jazzy install (launch/launch_ros are not installable in
this project's wheel-based environment, where the `bringup` executable does the same job).

    ros2 launch arm_bringup arm_pipeline.launch.py use_sim:=true
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

CONFIG = os.path.join(get_package_share_directory("arm_bringup"), "config")


def generate_launch_description():
    use_sim = LaunchConfiguration("use_sim")
    sim_time = {"use_sim_time": use_sim}  # the graph runs on the sim's /clock when the sim runs
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
            parameters=[os.path.join(CONFIG, "segmentation_node.yaml"), sim_time],
        ),
        Node(
            package="arm_reconstruction",
            executable="reconstruction_node",
            parameters=[os.path.join(CONFIG, "reconstruction_node.yaml"), sim_time],
        ),
        Node(
            package="arm_planner",
            executable="plan_node",
            parameters=[os.path.join(CONFIG, "plan_node.yaml"), sim_time],
        ),
    ]
    return LaunchDescription([DeclareLaunchArgument("use_sim", default_value="true")] + nodes)
