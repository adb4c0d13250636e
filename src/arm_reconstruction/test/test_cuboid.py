import numpy as np
import trimesh
from scipy import ndimage

from arm_reconstruction.cuboid import cuboid_completion, cuboid_mesh, fit_cuboid
from arm_reconstruction.grid import GridFrame, voxelize_mesh
from arm_reconstruction.metrics import chamfer_distance_m

CAMERA = np.array([0.6, 0.1, 0.5])


def _seen_side(mesh: trimesh.Trimesh, count: int = 4000, noise_m: float = 0.001, seed: int = 0):
    """Surface samples facing a camera at CAMERA, with their normals and noise (m)."""
    rng = np.random.default_rng(seed)
    points, faces = trimesh.sample.sample_surface(mesh, count, seed=seed)
    normals = mesh.face_normals[faces]
    facing = np.einsum("ij,ij->i", normals, CAMERA - points) > 0
    return points[facing] + rng.normal(0, noise_m, (facing.sum(), 3)), normals[facing]


def _box(extents, centre_xy, bottom_m: float, yaw_deg: float = 0.0) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=extents)
    box.apply_transform(trimesh.transformations.rotation_matrix(np.radians(yaw_deg), (0, 0, 1)))
    box.apply_translation((*centre_xy, bottom_m + extents[2] / 2))
    return box


def _frame() -> GridFrame:
    return GridFrame(np.array([-0.16, -0.16, 0.0]), 0.01, 32, 0.0)


def _seen_around(frame: GridFrame, *meshes) -> np.ndarray:
    """A four-channel grid whose voxels more than a voxel outside the meshes were seen empty (those at
    their surface hold their points; nothing else known)."""
    grid = np.zeros((4, frame.resolution, frame.resolution, frame.resolution), np.float32)
    solid = np.zeros(grid.shape[1:], bool)
    for mesh in meshes:
        solid |= voxelize_mesh(mesh, frame)
    grid[2] = ~ndimage.binary_dilation(solid)
    return grid


def test_a_turned_box_seen_from_one_corner_is_completed():
    for yaw_deg in (0.0, 25.0, 70.0):
        box = _box((0.09, 0.05, 0.14), (0.02, -0.01), 0.0, yaw_deg)
        points, normals = _seen_side(box)
        fit = fit_cuboid(points, normals, 0.0)
        assert fit is not None, yaw_deg
        cuboid = cuboid_mesh(fit)
        assert cuboid.is_watertight and cuboid.volume > 0
        assert chamfer_distance_m(cuboid, box) < 0.003, yaw_deg
        assert abs(cuboid.volume / box.volume - 1.0) < 0.1, yaw_deg


def test_cylinders_vases_and_spheres_are_not_cuboids():
    upright = trimesh.creation.cylinder(0.03, 0.14, sections=64)
    upright.apply_translation((0.0, 0.0, 0.07))
    lying = trimesh.creation.cylinder(0.03, 0.14, sections=64)
    lying.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    lying.apply_translation((0.0, 0.0, 0.03))
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.04)
    ball.apply_translation((0.0, 0.0, 0.04))
    for shape in (upright, lying, ball):
        points, normals = _seen_side(shape)
        assert fit_cuboid(points, normals, 0.0) is None


def test_a_box_on_a_box_rests_on_it_and_a_box_hidden_below_reaches_the_support():
    lower = _box((0.12, 0.09, 0.06), (0.0, 0.0), 0.0)
    upper = _box((0.08, 0.05, 0.05), (0.0, 0.0), 0.06, 10.0)
    points, normals = _seen_side(upper)
    grid = _seen_around(_frame(), lower, upper)
    stacked = cuboid_completion(points, normals, _frame(), grid, [lower])
    assert stacked is not None and abs(stacked.bounds[0, 2] - 0.06) < 0.004
    assert chamfer_distance_m(stacked, upper) < 0.003
    # the same seen walls with nothing reconstructed under them: hidden behind an object in front
    hidden = cuboid_completion(points, normals, _frame(), grid, [])
    assert hidden is not None and abs(hidden.bounds[0, 2]) < 1e-6


def test_a_box_seen_lower_than_the_object_in_front_of_it_stands_on_the_support():
    back = _box((0.08, 0.05, 0.12), (0.0, 0.0), 0.0)
    points, normals = _seen_side(back)
    seen = points[:, 2] > 0.03  # hidden below 3 cm by an object in front, whose completion reaches 5 cm
    front = _box((0.10, 0.08, 0.05), (0.05, 0.0), 0.0)
    grid = _seen_around(_frame(), back, front)
    cuboid = cuboid_completion(points[seen], normals[seen], _frame(), grid, [front])
    assert cuboid is not None and abs(cuboid.bounds[0, 2]) < 1e-6, "its walls pass in front of that top"


def test_a_cuboid_that_fills_seen_empty_space_is_refused():
    box = _box((0.09, 0.05, 0.14), (0.0, 0.0), 0.0)
    points, normals = _seen_side(box)
    grid = _seen_around(_frame(), box)
    assert cuboid_completion(points, normals, _frame(), grid) is not None
    grid[2] = 1.0
    assert cuboid_completion(points, normals, _frame(), grid) is None


def test_a_box_whose_far_side_another_object_hides_is_left_to_the_network():
    box = _box((0.09, 0.05, 0.14), (0.0, 0.0), 0.0)
    points, normals = _seen_side(box)
    grid = _seen_around(_frame(), box)

    def nothing_hidden(points_world):
        return np.zeros(len(points_world), bool)

    def hidden_behind_x(points_world):  # an object in front hides everything past x < -0.04
        return points_world[:, 0] < -0.04

    assert cuboid_completion(points, normals, _frame(), grid, hidden_by_others=nothing_hidden) is not None
    behind = grid.copy()
    behind[2][hidden_behind_x(_frame().voxel_centers_world().reshape(-1, 3)).reshape(behind.shape[1:])] = 0.0
    assert cuboid_completion(points, normals, _frame(), behind, hidden_by_others=nothing_hidden) is not None
    assert cuboid_completion(points, normals, _frame(), behind, hidden_by_others=hidden_behind_x) is None
    assert cuboid_completion(points, normals, _frame(), grid, hidden_by_others=hidden_behind_x) is not None, (
        "seen past along its edge"
    )
