import numpy as np
import pytest
import trimesh
from sensor_msgs.msg import JointState
from shape_msgs.msg import Mesh, MeshTriangle

from arm_interfaces.msg import ReconstructedObject, ReconstructedObjectArray
from arm_planner.messages import joint_state_arrays, trajectory_msg, twin_objects_from_msg
from arm_ros.conversions import ConversionError
from arm_ros.conversions.meshes import mesh_to_msg
from arm_ros.conversions.poses import matrix_to_pose


def _box_msg():
    box = trimesh.creation.box(extents=(0.05, 0.05, 0.05))
    return mesh_to_msg(box.vertices, box.faces)


def test_objects_from_message_keep_good_ones_and_explain_bad_ones():
    broken = Mesh(vertices=_box_msg().vertices, triangles=[MeshTriangle(vertex_indices=[0, 1, 99])])
    msg = ReconstructedObjectArray(table_height_m=0.1)
    msg.objects = [
        ReconstructedObject(id=1, pose=matrix_to_pose(np.eye(4)), mesh=_box_msg()),
        ReconstructedObject(id=2, pose=matrix_to_pose(np.eye(4)), mesh=broken),
        ReconstructedObject(id=3, pose=matrix_to_pose(np.eye(4))),
        ReconstructedObject(id=4, pose=matrix_to_pose(np.eye(4)), mesh=_box_msg(), convex_parts=[_box_msg()]),
    ]
    objects, table, dropped = twin_objects_from_msg(msg)
    assert table == pytest.approx(0.1)
    assert [o.id for o in objects] == [1, 4]
    assert objects[0].convex_parts == [] and len(objects[1].convex_parts) == 1
    assert set(dropped) == {2, 3}


def test_objects_larger_than_the_limit_are_dropped_with_their_size():
    huge = trimesh.creation.box(extents=(1e6, 1e6, 1e6))
    msg = ReconstructedObjectArray(table_height_m=0.0)
    msg.objects = [
        ReconstructedObject(id=1, pose=matrix_to_pose(np.eye(4)), mesh=_box_msg()),
        ReconstructedObject(id=2, pose=matrix_to_pose(np.eye(4)), mesh=mesh_to_msg(huge.vertices, huge.faces)),
    ]
    objects, _, dropped = twin_objects_from_msg(msg, max_object_size_m=1.0)
    assert [o.id for o in objects] == [1]
    assert "larger than max_object_size_m" in dropped[2]


def test_trajectory_message_times_and_positions():
    msg = trajectory_msg(["a", "b"], np.array([0.02, 1.5]), np.array([[0.0, 1.0], [2.0, 3.0]]))
    assert msg.joint_names == ["a", "b"]
    assert (msg.points[1].time_from_start.sec, msg.points[1].time_from_start.nanosec) == (1, 500_000_000)
    assert msg.points[0].time_from_start.nanosec == 20_000_000
    assert list(msg.points[1].positions) == [2.0, 3.0]


def test_trajectory_message_times_just_below_a_whole_second_stay_increasing():
    # a streamed part's times are plan times less the time executed: 0.02 * 50 - 0.16 is 0.9999999999999999
    times = 0.02 * np.arange(1, 60)[8:] - 0.16
    msg = trajectory_msg(["a"], times, np.zeros((len(times), 1)))
    ns = [p.time_from_start.sec * 1_000_000_000 + p.time_from_start.nanosec for p in msg.points]
    assert np.all(np.diff(ns) > 0)
    one_second = msg.points[int(np.argmin(np.abs(times - 1.0)))].time_from_start
    assert (one_second.sec, one_second.nanosec) == (1, 0)


def test_joint_states_are_checked():
    names = ["j1", "j2", "f"]
    q, opening = joint_state_arrays(JointState(name=names, position=[0.1, 0.2, 0.03]), ["j2", "j1"], "f")
    np.testing.assert_allclose(q, [0.2, 0.1])
    assert opening == pytest.approx(0.03)
    with pytest.raises(ConversionError, match="lacks"):
        joint_state_arrays(JointState(name=names[:2], position=[0.1, 0.2]), ["j1"], "f")
    with pytest.raises(ConversionError, match="non-finite"):
        joint_state_arrays(JointState(name=names, position=[np.nan, 0.2, 0.0]), ["j1"], "f")
