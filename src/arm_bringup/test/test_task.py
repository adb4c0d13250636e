import numpy as np
import trimesh

from arm_bringup.task import choose_target
from arm_interfaces.msg import ReconstructedObject
from arm_ros.conversions.meshes import mesh_to_msg
from arm_sim.world import ROBOT_BASE_XY


def _object(object_id: int, extents_m, xy, visible_fraction: float) -> ReconstructedObject:
    box = trimesh.creation.box(extents=extents_m)
    msg = ReconstructedObject(id=object_id, mesh=mesh_to_msg(box.vertices, box.faces))
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = float(xy[0]), float(xy[1]), 0.05
    msg.pose.orientation.w = 1.0
    msg.visible_fraction = visible_fraction
    return msg


def test_a_grasp_goes_to_the_most_visible_reachable_object_the_open_gripper_can_span():
    near = np.array(ROBOT_BASE_XY) + [0.4, 0.0]
    wide = _object(1, (0.20, 0.15, 0.1), near, 1.0)
    narrow = _object(2, (0.05, 0.12, 0.1), near + [0.0, 0.1], 0.6)
    narrow_far = _object(3, (0.05, 0.05, 0.1), np.array(ROBOT_BASE_XY) + [1.5, 0.0], 0.9)
    objects = [wide, narrow, narrow_far]
    assert choose_target(objects, "grasp")[0].id == 2
    assert choose_target(objects, "rearrange")[0].id == 2
    assert choose_target(objects, "push")[0].id == 1
    target, why = choose_target([wide, narrow_far], "rearrange")
    assert target.id == 1 and "pushed" in why


def test_no_target_suits_the_task_and_the_reason_says_why():
    wide = _object(1, (0.20, 0.15, 0.1), np.array(ROBOT_BASE_XY) + [0.4, 0.0], 1.0)
    far = _object(2, (0.05, 0.05, 0.1), np.array(ROBOT_BASE_XY) + [1.5, 0.0], 0.9)
    target, why = choose_target([wide, far], "grasp")
    assert target is None and "fits between the open fingers" in why
    target, why = choose_target([far], "push")
    assert target is None and "within reach" in why and "1.5" in why
