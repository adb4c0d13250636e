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
    assert choose_target(objects, "grasp").id == 2
    assert choose_target(objects, "rearrange").id == 2
    assert choose_target(objects, "push").id == 1
    assert choose_target([wide, narrow_far], "grasp").id == 1
