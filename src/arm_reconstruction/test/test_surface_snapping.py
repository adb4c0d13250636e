import numpy as np
import trimesh

from arm_core.camera import intrinsics, look_at, normalized_coordinates, transform_points
from arm_reconstruction.metrics import chamfer_distance_m, is_closed
from arm_reconstruction.surface_snapping import SnapSettings, smoothed_object_depth, snap_to_observed_depth

WIDTH, HEIGHT = 160, 120


def _render_depth(mesh: trimesh.Trimesh, K, T_world_camera) -> np.ndarray:
    """z-depth (metres) of the first hit of each pixel's ray, 0 where it misses."""
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH]
    x, y = normalized_coordinates(v.ravel(), u.ravel(), K)
    directions_camera = np.stack([x, y, np.ones_like(x)], 1)
    directions = directions_camera @ T_world_camera[:3, :3].T
    origins = np.broadcast_to(T_world_camera[:3, 3], directions.shape)
    locations, rays, _ = mesh.ray.intersects_location(origins, directions, multiple_hits=False)
    depth = np.zeros(HEIGHT * WIDTH)
    depth[rays] = transform_points(locations, np.linalg.inv(T_world_camera))[:, 2]
    return depth.reshape(HEIGHT, WIDTH)


def _scene():
    truth = trimesh.creation.box((0.08, 0.06, 0.10))
    truth.apply_translation((0.0, 0.0, 0.05))
    K = intrinsics(WIDTH, HEIGHT, 45.0)
    T_world_camera = look_at((0.35, 0.30, 0.30), (0.0, 0.0, 0.05))
    depth = _render_depth(truth, K, T_world_camera)
    labels = np.where(depth > 0, 3, 0).astype(np.int32)
    return truth, K, T_world_camera, depth, labels


def test_seen_vertices_move_onto_the_observed_surface():
    truth, K, T_world_camera, depth, labels = _scene()
    coarse = trimesh.creation.box((0.092, 0.072, 0.10))  # 6 mm too wide on every side
    coarse.apply_translation((0.0, 0.0, 0.05))
    coarse = coarse.subdivide().subdivide().subdivide()
    settings = SnapSettings(smoothing_px=3, mask_erosion_px=1)
    object_depth = smoothed_object_depth(depth, labels, [3], settings)
    snapped, count = snap_to_observed_depth(coarse, object_depth, labels, 3, K, T_world_camera, 0.012, 0.0, settings)
    assert count > 50
    before = np.abs(trimesh.proximity.signed_distance(truth, coarse.vertices))
    after = np.abs(trimesh.proximity.signed_distance(truth, snapped.vertices))
    vertices = np.asarray(coarse.vertices)
    middle = np.abs(vertices[:, 2] - 0.05) < 0.03  # away from the top and bottom edges
    plus_x = (vertices[:, 0] > 0.045) & (np.abs(vertices[:, 1]) < 0.02) & middle
    plus_y = (vertices[:, 1] > 0.035) & (np.abs(vertices[:, 0]) < 0.03) & middle
    for seen_face in (plus_x, plus_y):
        assert seen_face.sum() >= 4 and after[seen_face].mean() < 0.3 * before[seen_face].mean()
    assert chamfer_distance_m(snapped, truth) < chamfer_distance_m(coarse, truth)
    assert is_closed(snapped) and len(snapped.faces) == len(coarse.faces)
    base = np.asarray(coarse.vertices)[:, 2] <= 1e-9
    assert np.allclose(np.asarray(snapped.vertices)[base, 2], 0.0)
    far_side = np.asarray(coarse.vertices)[:, 0] < -0.045  # faces away from the camera at +x
    assert np.allclose(np.asarray(snapped.vertices)[far_side], np.asarray(coarse.vertices)[far_side], atol=1e-3)


def test_nothing_moves_beyond_the_limit_or_on_another_objects_pixels():
    truth, K, T_world_camera, depth, labels = _scene()
    shifted = truth.copy().subdivide().subdivide()
    towards_camera = T_world_camera[:3, 3] - np.array([0.0, 0.0, 0.05])
    shifted.apply_translation(0.03 * towards_camera / np.linalg.norm(towards_camera))  # beyond a 1 cm limit
    object_depth = smoothed_object_depth(depth, labels, [3], SnapSettings())
    out, count = snap_to_observed_depth(shifted, object_depth, labels, 3, K, T_world_camera, 0.01, 0.0)
    assert count == 0 and np.array_equal(out.vertices, shifted.vertices)
    close = truth.copy().subdivide().subdivide()
    close.apply_translation((0.004, 0.0, 0.0))
    _, count = snap_to_observed_depth(close, object_depth, labels, 7, K, T_world_camera, 0.01, 0.0)
    assert count == 0


def test_object_depth_keeps_to_each_objects_own_pixels():
    depth = np.full((20, 20), 1.0, np.float32)
    depth[:, 10:] = 2.0
    labels = np.zeros((20, 20), np.int32)
    labels[:, :10], labels[:, 10:] = 1, 2
    out = smoothed_object_depth(depth, labels, [1, 2], SnapSettings(smoothing_px=5, mask_erosion_px=1))
    assert np.allclose(out[5:15, 1:9], 1.0) and np.allclose(out[5:15, 11:19], 2.0)
    assert (out[:, 9] == 0).all() and (out[:, 10] == 0).all()
    assert smoothed_object_depth(depth, labels, [5], SnapSettings()).max() == 0.0
