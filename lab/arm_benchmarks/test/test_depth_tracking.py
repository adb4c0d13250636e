"""Object poses from re-observation: a mesh fitted to the points a camera sees of it."""

import numpy as np
import trimesh

from arm_benchmarks.depth_tracking import DepthTracker, DepthTrackingParams, rotation_vector
from arm_core.camera import intrinsics, look_at


def _pose(yaw_rad: float, translation) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = translation
    return T


def _seen_points(mesh: trimesh.Trimesh, T_world_object: np.ndarray, eye) -> np.ndarray:
    """The surface points of the posed mesh whose faces look towards the camera at eye (world, m)."""
    posed = mesh.copy().apply_transform(T_world_object)
    points, faces = trimesh.sample.sample_surface_even(posed, 3000, seed=1)
    towards = np.einsum("ij,ij->i", posed.face_normals[faces], np.asarray(eye) - points) > 0
    return points[towards]


def test_rotation_vector_is_the_axis_times_the_angle_up_to_a_half_turn():
    for angle in (0.0, 0.3, 2.0, np.pi - 1e-4, np.pi):
        axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
        R = trimesh.transformations.rotation_matrix(angle, axis)[:3, :3]
        vector = rotation_vector(R)
        assert np.isclose(np.linalg.norm(vector), angle, atol=1e-6)
        if angle > 0:
            assert np.isclose(abs(vector @ axis), angle, atol=1e-4), "along the axis (either sign at a half turn)"


BOX = trimesh.creation.box(extents=(0.06, 0.04, 0.10))
EYE = (0.5, 0.3, 0.4)


def test_a_box_seen_from_one_side_is_found_where_it_moved():
    truth = _pose(0.3, (0.01, -0.005, 0.05))
    predicted = _pose(0.3 - np.radians(5.0), (0.0, 0.005, 0.05))
    tracker = DepthTracker({1: BOX})
    fitted = tracker.fit(1, _seen_points(BOX, truth, EYE), predicted)
    assert fitted is not None
    assert np.linalg.norm(fitted[:3, 3] - truth[:3, 3]) < 0.002
    assert np.degrees(np.linalg.norm(rotation_vector(fitted[:3, :3] @ truth[:3, :3].T))) < 1.0


def test_the_prediction_stands_out_of_view_within_the_noise_and_after_a_jump():
    truth = _pose(0.0, (0.0, 0.0, 0.05))
    tracker = DepthTracker({1: BOX}, DepthTrackingParams(min_points=30, max_shift_m=0.01))
    seen = _seen_points(BOX, truth, EYE)
    assert tracker.fit(1, seen[:10], truth) is None, "too few points"
    assert tracker.fit(2, seen, truth) is None, "no mesh for that id"
    assert tracker.fit(1, seen + [0.0, 0.0, 0.001], truth) is None, "1 mm off: depth noise"
    assert tracker.fit(1, seen + [0.0, 0.0, 0.03], truth) is None, "3 cm from the prediction, more than max_shift_m"
    assert tracker.fit(1, seen + [0.0, 0.0, 0.006], truth) is not None, "6 mm: a motion"


def test_a_solid_of_revolution_is_not_spun_about_its_axis():
    can = trimesh.creation.cylinder(radius=0.03, height=0.1, sections=64)
    truth = _pose(0.0, (0.0, 0.0, 0.058))
    predicted = _pose(0.3, (0.0, 0.0, 0.05))  # 8 mm low, and turned by an angle no view can tell
    fitted = DepthTracker({1: can}).fit(1, _seen_points(can, truth, EYE), predicted)
    assert fitted is not None
    assert abs(fitted[2, 3] - 0.058) < 0.001, "lifted as seen"
    assert abs(np.linalg.norm(rotation_vector(fitted[:3, :3])) - 0.3) < 0.02, "the spin stays as predicted"


def test_track_fits_each_object_to_its_own_pixels():
    K = intrinsics(160, 120, 60.0)
    T_world_camera = look_at(np.array(EYE), np.array([0.0, 0.0, 0.05]))
    truth = _pose(0.0, (0.0, 0.0, 0.05))
    # A depth image of the box's camera-facing faces, by casting each pixel's ray at it.
    posed = BOX.copy().apply_transform(truth)
    v, u = np.mgrid[0:120, 0:160]
    rays = np.stack([(u.ravel() - K[0, 2]) / K[0, 0], (v.ravel() - K[1, 2]) / K[1, 1], np.ones(v.size)], 1)
    directions = rays @ T_world_camera[:3, :3].T
    origins = np.broadcast_to(T_world_camera[:3, 3], directions.shape)
    hits, ray_index, _ = posed.ray.intersects_location(origins, directions, multiple_hits=False)
    depth = np.zeros(v.size, np.float32)
    depth[ray_index] = (hits - T_world_camera[:3, 3]) @ T_world_camera[:3, 2]
    depth = depth.reshape(120, 160)
    labels = (depth > 0).astype(np.uint16)
    predicted = {1: _pose(0.05, (0.01, 0.0, 0.05)), 2: _pose(0.0, (0.2, 0.0, 0.05))}
    fitted = DepthTracker({1: BOX, 2: BOX}).track(depth, labels, K, T_world_camera, predicted)
    assert set(fitted) == {1}, "object 2 has no pixels"
    assert np.linalg.norm(fitted[1][:3, 3] - truth[:3, 3]) < 0.003
