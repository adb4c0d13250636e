import numpy as np
import trimesh

from arm_planner.finger_clearance import OpenFingers, clearance_m, finger_points, halfspaces
from arm_planner.grasp_site import GraspTarget, Occupancy, find_grasp_site, inside_parts
from arm_planner.tasks.base import TargetGeometry
from arm_planner.tasks.grasp import GraspReward
from arm_planner.twin import decompose

FINGERS = OpenFingers(gap_m=0.082, thickness_m=0.012, width_m=0.02, length_m=0.055, tcp_above_tip_m=0.007)


def _on_table(mesh: trimesh.Trimesh, xy=(0.5, 0.1)) -> trimesh.Trimesh:
    mesh = mesh.copy()
    mesh.apply_translation([xy[0], xy[1], -mesh.bounds[0][2]])
    return mesh


def _parts(mesh: trimesh.Trimesh):
    parts = decompose(mesh)
    return [halfspaces(p) for p in parts], np.concatenate([p.vertices for p in parts])


def _site(mesh: trimesh.Trimesh, obstacles=None, axis=(1.0, 0.0, 0.0)):
    planes, vertices = _parts(mesh)
    com = mesh.center_mass
    top = vertices[:, 2].max()
    default = np.array([com[0], com[1], max(np.clip(com[2], top - 0.04, top - 0.015), 0.015)])
    target = GraspTarget(com, vertices, planes, 0.0, 0.015, 0.04, obstacles)
    site = find_grasp_site(default, np.array(axis), target, FINGERS)
    return site, default, planes, com


def _u_shape() -> trimesh.Trimesh:
    """A U 14 cm wide and 12 cm deep of 3 cm walls, 6 cm tall, open towards +y."""
    walls = [((0.14, 0.03, 0.06), (0.0, -0.045, 0.03)), ((0.03, 0.12, 0.06), (-0.055, 0.0, 0.03))]
    walls.append(((0.03, 0.12, 0.06), (0.055, 0.0, 0.03)))
    boxes = []
    for size, centre in walls:
        box = trimesh.creation.box(size)
        box.apply_translation(centre)
        boxes.append(box)
    return _on_table(trimesh.util.concatenate(boxes))


def test_inside_parts_and_the_voxel_columns_agree_with_the_box():
    box = _on_table(trimesh.creation.box((0.04, 0.06, 0.10)))
    planes = [halfspaces(box)]
    assert inside_parts(np.array([[0.5, 0.1, 0.05], [0.53, 0.1, 0.05]]), planes).tolist() == [True, False]
    grid = Occupancy.from_parts(planes, box.bounds[0] - 0.01, box.bounds[1] + 0.01, 0.004)
    column = grid.columns(np.array([0.5, 0.1]))
    assert 0.09 <= column.sum() * 0.004 <= 0.11
    assert not grid.columns(np.array([0.9, 0.1])).any(), "outside the grid is empty"


def test_a_solid_object_that_fits_keeps_the_site_over_its_centre_of_mass_bit_for_bit():
    site, default, _, _ = _site(_on_table(trimesh.creation.box((0.05, 0.06, 0.10))))
    assert not site.moved
    assert np.array_equal(site.point_world, default)


def test_a_torus_is_grasped_on_its_tube_closing_across_it():
    torus = _on_table(trimesh.creation.torus(0.075, 0.025))
    site, _, planes, com = _site(torus)
    assert site.moved, "the centre of a torus is its hole"
    radial = site.point_world[:2] - com[:2]
    assert 0.055 <= np.linalg.norm(radial) <= 0.095, "on the tube"
    assert abs(radial @ site.axis_xy[:2]) / np.linalg.norm(radial) > 0.9, "closing across the tube"
    assert clearance_m(finger_points(site.point_world, site.axis_xy[:2], FINGERS), planes) > -0.002
    assert 0.01 <= site.point_world[2] <= 0.05


def test_a_u_is_grasped_on_a_wall_with_square_faces_between_the_fingers():
    u_shape = _u_shape()
    site, _, planes, _ = _site(u_shape)
    assert site.moved, "the centre of mass of this U lies in its channel"
    on_wall = np.array([site.point_world, site.point_world - [0.0, 0.0, 0.01]])
    assert inside_parts(on_wall, planes).any(), "the TCP sits in a wall's material"
    axis = np.abs(site.axis_xy[:2])
    assert max(axis) > 0.95, "the fingers close square to a wall, not across a corner"


def test_an_object_wider_than_the_gap_everywhere_keeps_the_default():
    site, default, _, _ = _site(_on_table(trimesh.creation.box((0.20, 0.20, 0.10))))
    assert not site.moved and np.array_equal(site.point_world, default)


def test_a_site_whose_fingers_would_enter_a_neighbour_is_passed_over():
    torus = _on_table(trimesh.creation.torus(0.075, 0.025))
    free, _, _, _ = _site(torus)
    block = trimesh.creation.box((0.06, 0.06, 0.10))
    block.apply_translation([*free.point_world[:2], 0.05])
    site, _, _, _ = _site(torus, obstacles=[halfspaces(block)])
    assert site.moved
    assert clearance_m(finger_points(site.point_world, site.axis_xy[:2], FINGERS), [halfspaces(block)]) >= 0


def test_the_grasp_reward_moves_its_grasp_point_and_offset_to_the_site():
    torus = _on_table(trimesh.creation.torus(0.075, 0.025))
    planes, vertices = _parts(torus)
    geometry = TargetGeometry(torus.center_mass, vertices, 0.0, part_halfspaces=planes)
    options = dict(hand=None, target=None, qpos_offset=0, nq=0)
    searched = GraspReward(geometry=geometry, fingers=FINGERS, **options)
    assert searched.grasp_site_moved
    assert np.linalg.norm(searched.grasp_offset[:2]) > 0.05
    kept = GraspReward(geometry=geometry, fingers=FINGERS, search_grasp_site=False, **options)
    assert not kept.grasp_site_moved and np.allclose(kept.grasp_point[:2], torus.center_mass[:2])


def test_only_a_target_no_site_holds_and_wider_than_the_fingers_every_way_is_ungraspable():
    options = dict(hand=None, target=None, qpos_offset=0, nq=0, fingers=FINGERS)
    verdicts = {}
    for name, mesh in [("wide box", trimesh.creation.box((0.15, 0.15, 0.06))), ("u", _u_shape())]:
        mesh = _on_table(mesh)
        planes, vertices = _parts(mesh)
        geometry = TargetGeometry(mesh.center_mass, vertices, 0.0, part_halfspaces=planes)
        verdicts[name] = GraspReward(geometry=geometry, **options).ungraspable
    assert verdicts == {"wide box": True, "u": False}


def test_a_target_narrower_than_the_fingers_along_some_axis_is_never_ungraspable():
    box = _on_table(trimesh.creation.box((0.06, 0.20, 0.06)))
    planes, vertices = _parts(box)
    geometry = TargetGeometry(box.center_mass, vertices, 0.0, part_halfspaces=planes)
    reward = GraspReward(geometry=geometry, hand=None, target=None, qpos_offset=0, nq=0, fingers=FINGERS)
    reward.grasp_site_holds = False  # as a lumpy reconstruction can leave it
    assert not reward.ungraspable
