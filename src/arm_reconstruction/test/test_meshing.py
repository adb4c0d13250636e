import numpy as np
import pytest
import trimesh
from scipy import ndimage

from arm_core.camera import look_at
from arm_reconstruction.grid import GridFrame, frame_grids, voxelize_mesh
from arm_reconstruction.meshing import (
    _axis_path,
    add_missed_observed_voxels,
    connect_parts,
    drop_small_components,
    extrude_to_table,
    keep_observed_components,
    occupancy_mesh,
    ray_carve,
    remove_intersections,
    rests_on_support,
    support_from_below,
    to_manifold,
    widen_unstable_base,
)
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene
from arm_sim.world import SimWorld


@pytest.fixture(scope="module")
def sim_frame():
    rng = np.random.default_rng(3)
    scene = cluttered_scene(object_pool(split="train", seed=0), rng, n_objects=6)
    world = SimWorld(scene, robot_arm=False, width=320, height=240)
    frame = world.render(look_at((0.7, 0.3, 0.5), scene.objects[0].T_world_object[:3, 3]), rng=rng)
    world.close()
    grids = frame_grids(frame.depth_m, frame.K, frame.T_world_camera, frame.labels)
    truth = [scene.objects[i - 1].world_mesh() for i in grids.object_ids]
    return grids, truth


def test_ground_truth_occupancy_round_trips_to_a_watertight_world_mesh(sim_frame):
    grids, truth = sim_frame
    for frame, true_mesh in zip(grids.frames, truth, strict=True):
        occupancy = voxelize_mesh(true_mesh, frame)
        mesh = occupancy_mesh(occupancy.astype(np.float32), frame)
        assert mesh.is_watertight and mesh.volume > 0 and to_manifold(mesh) is not None
        lo, hi = np.asarray(frame.origin_world), np.asarray(frame.origin_world) + frame.side_m
        assert np.all(mesh.bounds[0] >= lo - 1e-6) and np.all(mesh.bounds[1] <= hi + 1e-6)
        voxel_volume = occupancy.sum() * frame.voxel_size_m**3
        assert 0 < mesh.volume <= voxel_volume * 1.0001
        centres = frame.voxel_centers_world()[occupancy]
        gap = np.linalg.norm(mesh.vertices[:, None] - centres[None], axis=-1).min(1)
        assert gap.max() <= frame.voxel_size_m * 0.5 * 3**0.5 + 1e-9


def test_a_shape_on_the_table_touches_the_table_plane():
    frame = GridFrame(np.array([0.0, 0.0, 0.2]), 0.01, 16, 0.2)
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[4:8, 4:8, 0:5] = 0.9
    mesh = occupancy_mesh(probabilities, frame)
    assert mesh.bounds[0, 2] == pytest.approx(0.2, abs=1e-9)
    top_crossing = (0.9 - 0.5) / 0.9
    assert mesh.bounds[1, 2] == pytest.approx(0.2 + (4.5 + top_crossing) * 0.01, abs=1e-6)
    assert mesh.is_watertight


def test_variants_ray_carving_and_extrusion():
    frame = GridFrame(np.zeros(3), 0.01, 16, 0.0)
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[5:9, 5:9, 6:10] = 0.8
    extruded = extrude_to_table(probabilities)
    assert np.all(extruded[5:9, 5:9, 0:10] == 0.8) and extruded[5:9, 5:9, 10:].max() == 0
    assert extruded[:5].max() == 0
    mesh = occupancy_mesh(extruded, frame)
    assert mesh.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)
    grid = np.zeros((4, 16, 16, 16), np.float32)
    grid[2, 5:7] = 1.0
    carved = ray_carve(probabilities, grid)
    assert carved[5:7].max() == 0 and np.all(carved[7:9, 5:9, 6:10] == 0.8)


def test_specks_are_dropped_and_bad_probabilities_are_handled():
    frame = GridFrame(np.zeros(3), 0.01, 16, 0.0)
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[2:6, 2:6, 2:6] = 1.0
    probabilities[12, 12, 12] = 1.0
    cleaned = drop_small_components(probabilities, 0.5, 4)
    assert cleaned[12, 12, 12] == 0 and cleaned[2:6, 2:6, 2:6].min() == 1
    lone = np.zeros((16, 16, 16), np.float32)
    lone[3, 3, 0:2] = 0.9
    lone[9, 9, 9] = 0.9
    kept = drop_small_components(lone, 0.5, 4)
    assert kept[3, 3, 0] == 0.9 and kept[9, 9, 9] == 0, "the largest component survives even when small"
    assert occupancy_mesh(lone, frame).is_watertight
    assert len(occupancy_mesh(probabilities, frame).split(only_watertight=False)) == 1
    assert len(occupancy_mesh(np.zeros((16, 16, 16), np.float32), frame).faces) == 0
    with_nan = probabilities.copy()
    with_nan[0, 0, 0] = np.nan
    assert occupancy_mesh(with_nan, frame).is_watertight
    with pytest.raises(ValueError, match="shape"):
        occupancy_mesh(np.zeros((8, 8, 8)), frame)
    with pytest.raises(ValueError, match="threshold"):
        occupancy_mesh(probabilities, frame, threshold=1.0)


def test_components_apart_from_the_observed_voxels_are_dropped():
    frame = GridFrame(np.zeros(3), 0.01, 16, 0.0)
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[2:5, 2:5, 0:4] = 0.9  # holds the observed voxels
    probabilities[10:15, 10:15, 0:6] = 0.8  # larger, but nowhere near what was seen
    observed = np.zeros((16, 16, 16), np.float32)
    observed[5, 3, 1] = 1.0  # one voxel beside the first component
    kept = keep_observed_components(probabilities, 0.5, observed)
    assert kept[2:5, 2:5, 0:4].min() == 0.9 and kept[10:15, 10:15].max() == 0
    assert np.array_equal(keep_observed_components(probabilities, 0.5, np.zeros_like(observed)), probabilities)
    far = np.zeros_like(observed)
    far[8, 0, 12] = 1.0
    assert np.array_equal(keep_observed_components(probabilities, 0.5, far), probabilities), "none touch: unchanged"
    mesh = occupancy_mesh(probabilities, frame, grid=np.stack([observed] + [np.zeros_like(observed)] * 3))
    assert len(mesh.split(only_watertight=False)) == 1 and mesh.bounds[1, 0] < 0.06


def test_observed_voxels_the_network_missed_are_added_but_not_its_surface_noise():
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[4:8, 4:8, 6:10] = 0.9  # the network kept the top of the object only
    observed = np.zeros_like(probabilities)
    observed[4, 4:8, 0:10] = 1.0  # the seen face runs down to the table
    observed[3, 5, 7] = 1.0  # depth noise one voxel outside the predicted surface
    added = add_missed_observed_voxels(probabilities, 0.5, observed)
    assert added[4, 4:8, 0:5].min() == 1.0, "the missed lower part of the seen face is added"
    assert added[3, 5, 7] == 0.0, "observed voxels next to the prediction are left to it"
    assert np.array_equal(added[probabilities > 0], probabilities[probabilities > 0])
    assert np.array_equal(add_missed_observed_voxels(probabilities, 0.5, np.zeros_like(observed)), probabilities)
    mesh = occupancy_mesh(
        added, GridFrame(np.zeros(3), 0.01, 16, 0.0), grid=np.stack([observed] + [np.zeros_like(observed)] * 3)
    )
    assert mesh.bounds[0, 2] < 0.005, "the mesh reaches down to the table"


def test_an_observed_voxel_joining_two_predicted_parts_is_added():
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[4:8, 4:8, 0:4] = 0.9  # base
    probabilities[4:8, 4:8, 5:9] = 0.9  # top, one layer above it
    observed = np.zeros_like(probabilities)
    observed[5, 5, 4] = 1.0  # seen in the gap, next to both
    observed[3, 5, 2] = 1.0  # seen beside the base only: surface noise
    added = add_missed_observed_voxels(probabilities, 0.5, observed)
    assert added[5, 5, 4] == 1.0 and added[3, 5, 2] == 0.0
    grid = np.stack([observed] + [np.zeros_like(observed)] * 3)
    mesh = occupancy_mesh(added, GridFrame(np.zeros(3), 0.01, 16, 0.0), grid=grid)
    assert len(mesh.split(only_watertight=False)) == 1


def test_the_seen_footprint_next_to_a_thin_stem_is_added_and_the_object_stands():
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[7, 7, 0:8] = 0.9  # one-voxel stem
    probabilities[5:10, 5:10, 8:12] = 0.9  # bowl
    observed = np.zeros_like(probabilities)
    observed[6:9, 6:9, 0] = 1.0  # the base disk, seen on the table around the stem
    observed[6, 7, 3] = 1.0  # seen beside the stem above the table: surface noise
    added = add_missed_observed_voxels(probabilities, 0.5, observed)
    assert added[6:9, 6:9, 0].min() > 0.5, "the footprint on the table is the object's"
    assert added[6, 7, 3] == 0.0
    grid = np.stack([observed] + [np.zeros_like(observed)] * 3)
    mesh = occupancy_mesh(added, GridFrame(np.zeros(3), 0.01, 16, 0.0), grid=grid)
    footprint = mesh.vertices[mesh.vertices[:, 2] < 1e-6, :2]
    assert np.ptp(footprint, axis=0).min() >= 0.02, "a base three voxels wide, not a point"
    assert np.all(footprint.min(0) < mesh.center_mass[:2]) and np.all(mesh.center_mass[:2] < footprint.max(0))


def test_a_floating_object_is_extended_down_through_unobserved_space_only():
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[4:8, 4:8, 6:10] = 0.9  # the seen top of an object whose lower part is occluded
    grid = np.zeros((4, 16, 16, 16), np.float32)
    grid[3, :, :, :6] = 1.0  # unobserved below it
    grid[3, 4, 4:8, :6] = 0.0
    grid[2, 4, 4:8, :6] = 1.0  # ... except one column row seen to be empty
    assert not rests_on_support(probabilities > 0.5, grid[1])
    supported = support_from_below(probabilities, 0.5, grid)
    assert supported[5:8, 4:8, 0:6].min() == 1.0 and supported[4, 4:8, 0:6].max() == 0.0
    assert rests_on_support(supported > 0.5, grid[1])
    assert np.array_equal(support_from_below(supported, 0.5, grid), supported), "supported: unchanged"
    on_other = grid.copy()
    on_other[1, 4:8, 4:8, 5] = 1.0  # another object seen right below it
    assert np.array_equal(support_from_below(probabilities, 0.5, on_other), probabilities)
    mesh = occupancy_mesh(probabilities, GridFrame(np.zeros(3), 0.01, 16, 0.0), grid=grid)
    assert mesh.bounds[0, 2] < 0.001, "the mesh stands on the table"


def test_a_top_heavy_object_on_a_point_gains_a_base_where_the_view_allows():
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[7, 7, 0:8] = 0.9  # one-voxel stem
    probabilities[4:11, 4:11, 8:11] = 0.9  # a heavy shade on top
    grid = np.zeros((4, 16, 16, 16), np.float32)
    grid[3] = 1.0  # nothing seen around it
    grid[3, 4:11, 10, 0] = 0.0
    grid[2, 4:11, 10, 0] = 1.0  # one row of the table under the shade seen empty
    widened = widen_unstable_base(probabilities, 0.5, grid, tilt_deg=10.0)
    base = widened[:, :, 0] > 0.5
    assert base[7, 7] and base.sum() > 1 and not base[:, 10].any(), "a base, not where the table was seen"
    assert not base[:4].any() and not base[11:].any(), "inside the object's own shadow"
    assert np.array_equal(widened[:, :, 1:], probabilities[:, :, 1:])
    assert np.array_equal(widen_unstable_base(probabilities, 0.5, grid, tilt_deg=0.0), probabilities), "off"
    box = np.zeros_like(probabilities)
    box[4:11, 4:11, 0:8] = 0.9  # a box stands on its whole footprint: unchanged
    assert np.array_equal(widen_unstable_base(box, 0.5, grid, tilt_deg=10.0), box)
    lifted = np.roll(probabilities, 2, axis=2)  # on something else, not the table: unchanged
    assert np.array_equal(widen_unstable_base(lifted, 0.5, grid, tilt_deg=10.0), lifted)


@pytest.mark.parametrize("end", [(3, 5, 7), (0, 0, 0), (9, 1, 0), (0, 0, 9)])
def test_join_paths_are_six_connected_along_the_line(end):
    path = _axis_path(np.array([0, 0, 0]), np.array(end))
    assert tuple(path[0]) == (0, 0, 0) and tuple(path[-1]) == end
    assert len(path) == sum(end) + 1 and (np.abs(np.diff(path, axis=0)).sum(axis=1) == 1).all()


def test_separate_parts_are_joined_unless_the_view_forbids_it():
    probabilities = np.zeros((16, 16, 16), np.float32)
    probabilities[5:10, 5:10, 8:12] = 0.9  # a bowl...
    probabilities[5:10, 5:10, 0] = 0.9  # ... above its base: the stem was not predicted
    grid = np.zeros((4, 16, 16, 16), np.float32)
    grid[3] = 1.0
    joined = connect_parts(probabilities, 0.5, grid)
    assert ndimage.label(joined > 0.5)[1] == 1
    added = (joined > 0.5) & ~(probabilities > 0.5)
    assert added.sum() == 7 and len(np.unique(np.argwhere(added)[:, :2], axis=0)) == 1, "a one-voxel stem"
    seen_through = grid.copy()
    seen_through[2, :, :, 3] = 1.0  # the camera saw the layer under the bowl empty
    assert np.array_equal(connect_parts(probabilities, 0.5, seen_through), probabilities), "big parts stay"
    mesh = occupancy_mesh(probabilities, GridFrame(np.zeros(3), 0.01, 16, 0.0), grid=grid)
    assert len(mesh.split(only_watertight=False)) == 1
    apart = occupancy_mesh(probabilities, GridFrame(np.zeros(3), 0.01, 16, 0.0), grid=grid, join_parts=False)
    assert len(apart.split(only_watertight=False)) == 2


def test_intersections_are_cut_from_the_larger_mesh():
    big = trimesh.creation.box((0.2, 0.2, 0.2))
    small = trimesh.creation.box((0.1, 0.1, 0.1)).apply_translation((0.1, 0.0, 0.0))
    apart = trimesh.creation.box((0.05, 0.05, 0.05)).apply_translation((1.0, 0.0, 0.0))
    (big_cut, small_kept, apart_kept), cuts = remove_intersections([big, small, apart])
    assert cuts == 1
    assert small_kept is small and apart_kept is apart
    assert big_cut.is_watertight
    assert big_cut.volume == pytest.approx(0.2**3 - 0.5 * 0.1**3, rel=1e-5)
    overlap = to_manifold(big_cut) ^ to_manifold(small_kept)
    assert overlap.volume() < 1e-12
    (a, b), cuts = remove_intersections([small, big])
    assert cuts == 1 and a is small and b.volume == pytest.approx(big_cut.volume, rel=1e-6)


def test_intersections_between_reconstructed_meshes(sim_frame):
    grids, truth = sim_frame
    frame = grids.frames[0]
    occupancy = voxelize_mesh(truth[0], frame).astype(np.float32)
    shifted = np.roll(occupancy, 2, axis=0)
    first, second = occupancy_mesh(occupancy, frame), occupancy_mesh(0.9 * shifted + 0.05, frame)
    (first_cut, second_cut), cuts = remove_intersections([first, second])
    assert cuts == 1
    overlap = to_manifold(first_cut) ^ to_manifold(second_cut)
    assert overlap.volume() < 1e-3 * min(first.volume, second.volume)
