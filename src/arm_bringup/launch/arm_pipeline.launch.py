"""Launch the ARM node graph on a full ROS 2 Jazzy install (launch/launch_ros are not installable in
this project's wheel-based environment, where the `bringup` executable does the same job).

    ros2 launch arm_bringup arm_pipeline.launch.py use_sim:=true
    ros2 launch arm_bringup arm_pipeline.launch.py camera:=realsense_d4xx   # a real camera, no simulator

The graph runs on the sim's /clock when the sim runs. camera:=<preset> (config/cameras/<preset>.yaml
or a path, see arm_bringup/camera_presets.py) remaps the camera topics to the driver's and sets the
preset's parameters; the simulator is then not started.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch_ros.actions import Node

from arm_bringup.camera_presets import load_preset, node_parameters, node_remappings
from arm_ros.processes import NODES  # bringup key: (package, executable, parameter file), as `bringup` runs them

CONFIG = os.path.join(get_package_share_directory("arm_bringup"), "config")


def graph_nodes(context):
    camera = context.launch_configurations.get("camera", "")
    preset = load_preset(camera) if camera else None
    use_sim = preset is None and context.launch_configurations.get("use_sim", "true").lower() in ("true", "1")
    nodes = []
    for key, (package, executable, params_file) in NODES.items():
        if key == "sim" and not use_sim:
            continue
        parameters = [os.path.join(CONFIG, params_file)]
        if key != "sim":
            parameters.append({"use_sim_time": use_sim})
        remappings = []
        if preset is not None:
            parameters.append(node_parameters(preset, key))
            remappings = list(node_remappings(preset, key).items())
        nodes.append(Node(package=package, executable=executable, parameters=parameters, remappings=remappings))
    return nodes


def generate_launch_description():
    return LaunchDescription(
        [
            DeclareLaunchArgument("use_sim", default_value="true"),
            DeclareLaunchArgument("camera", default_value="", description="camera preset: no simulator"),
            OpaqueFunction(function=graph_nodes),
        ]
    )
