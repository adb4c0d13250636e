"""segmentation_node's settings: the segmentation's (SegmentationParams) and the node's.

The node declares the settings marked as parameters (arm_core.settings); config/segmentation_node.yaml
is rendered from this dataclass."""

from __future__ import annotations

from dataclasses import dataclass, field

from arm_core.settings import GoalPauseSettings, cpu_niceness_setting, setting
from arm_segmentation.segmentation import SegmentationParams

POSE_SOURCES = ("topic", "tf", "estimate")


@dataclass
class SegmentationNodeConfig:
    segmentation: SegmentationParams = field(default_factory=SegmentationParams)
    use_ground_truth_masks: bool = setting(
        False,
        "Pass the simulator's label image through instead of segmenting (the paper's robot experiments)",
        parameter=True,
    )
    camera_pose_source: str = setting(
        "topic",
        "T_world_camera from camera/pose (topic), from /tf between world_frame and the camera's optical frame "
        "(tf), or estimated from the depth's table plane (estimate: published on /tf as the frame 'table')",
        choices=POSE_SOURCES,
        parameter=True,
    )
    world_frame: str = setting("world", "With tf: the gravity-aligned frame (z up) the robot plans in", parameter=True)
    camera_frame: str = setting(
        "",
        "The camera's optical frame for /tf (the camera presets set the driver's; '': each depth image's frame_id)",
        parameter=True,
    )
    image_reliability: str = setting(
        "best_effort",
        "Image subscriptions' QoS reliability (best_effort also matches reliable publishers)",
        choices=("best_effort", "reliable"),
        parameter=True,
    )
    sync_tolerance_s: float = setting(
        0.02,
        "Largest stamp difference between rgb, depth, camera_info and pose of one frame, s",
        0.0,
        1.0,
        parameter=True,
    )
    sync_queue_size: int = setting(5, "Messages kept per input while matching stamps", 1, 50)
    self_filter: bool = setting(
        True, "Mask the robot's own arm, rendered from /joint_states, out of the objects", parameter=True
    )
    robot_base_xyz_m: list = setting(
        [-0.55, 0.0, 0.0], "World position of the robot base, m (the same as plan_node's)", parameter=True
    )
    robot_base_yaw_rad: float = setting(
        0.0, "Yaw of the robot base about world +z, rad", -3.1416, 3.1416, parameter=True
    )
    self_filter_padding_m: float = setting(0.03, "Margin around the arm's links, m", 0.0, 0.5)
    cpu_niceness: int = cpu_niceness_setting()
    goal_pause: GoalPauseSettings = field(default_factory=GoalPauseSettings)
