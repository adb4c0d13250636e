"""sim_node's settings; the node declares those marked as parameters (arm_core.settings), and
config/sim_node.yaml is rendered from this dataclass."""

from __future__ import annotations

from dataclasses import dataclass, field

from arm_core.settings import GoalPauseSettings, setting
from arm_sim.appearance import DEFAULT_DOMAIN, DOMAINS


@dataclass
class SimNodeConfig:
    seed: int = setting(7, "Scene seed", 0, 2**31 - 1, parameter=True)
    objects: str = setting("", "Folder of .obj/.stl/.ply meshes, metres ('': the procedural library)", parameter=True)
    split: str = setting("heldout", "Procedural categories", choices=("train", "heldout"))
    n_objects: int = setting(
        8, "Objects in the scene (0: uniform(3, 20), as in the paper's benchmark)", 0, 40, parameter=True
    )
    visual_domain: str = setting(
        DEFAULT_DOMAIN,
        "realistic: textured objects, furniture, varied light, camera response and sensor artefacts; "
        "plain: one flat colour per object on a plain table",
        choices=DOMAINS,
        parameter=True,
    )
    camera_rate_hz: float = setting(2.0, "RGB-D publish rate, simulated time", 0.1, 30.0, parameter=True)
    physics_rate_hz: float = setting(50.0, "Control and physics tick rate", 10.0, 500.0)
    camera_eye: list = setting([0.7, 0.0, 0.5], "Camera position in the world, m", parameter=True)
    camera_target: list = setting([0.0, 0.0, 0.05], "Point the camera looks at, m", parameter=True)
    depth_noise: bool = setting(True, "Apply the depth-sensor noise model")
    width: int = setting(640, "Image width, pixels", 64, 1920, parameter=True)
    height: int = setting(480, "Image height, pixels", 48, 1080, parameter=True)
    fovy_deg: float = setting(45.0, "Vertical field of view, degrees", 10.0, 120.0, parameter=True)
    world_frame_id: str = setting("world", "World frame id")
    camera_frame_id: str = setting("camera_color_optical_frame", "Optical frame id", parameter=True)
    image_reliability: str = setting(
        "reliable", "Image QoS reliability", choices=("reliable", "best_effort"), parameter=True
    )
    arm_controller: str = setting("arm_controller", "Arm controller: serves <name>/follow_joint_trajectory")
    gripper_controller: str = setting("gripper_controller", "Gripper controller: serves <name>/gripper_cmd")
    # Rendering shares the CPU with the planner (a real camera does not): frames wait during goals.
    goal_pause: GoalPauseSettings = field(default_factory=GoalPauseSettings)
