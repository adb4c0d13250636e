import numpy as np
import pytest
from seg_fixtures import Box, add_noise, intrinsics, look_at, render

from arm_segmentation.camera_pose_estimate import (
    CameraPoseError,
    CameraPoseParams,
    estimate_camera_pose,
    plane_inlier_fraction,
    plane_problem,
    world_from_plane,
)
from arm_segmentation.pose_tracking import CameraPoseTracker
from arm_sim.objects import object_pool
from arm_sim.views import render_benchmark_view


def gravity_error_deg(T_estimate, T_true):
    """Angle between the estimated and the true world-up, both in the camera frame."""
    return float(np.degrees(np.arccos(np.clip(T_estimate[2, :3] @ T_true[2, :3], -1.0, 1.0))))


BOXES = [
    Box((0.05, -0.1, 0.05), (0.05, 0.04, 0.05), 0.3, (200, 40, 40)),
    Box((-0.05, 0.1, 0.08), (0.03, 0.03, 0.08), 0.0, (40, 170, 60)),
    Box((0.15, 0.12, 0.03), (0.06, 0.06, 0.03), 0.8, (40, 60, 200)),
]


@pytest.mark.parametrize(
    "eye, target",
    [((-0.6, 0.2, 0.5), (0.0, 0.0, 0.0)), ((0.3, -0.4, 0.9), (0.05, 0.05, 0.0)), ((0.0, 0.01, 0.7), (0.0, 0.0, 0.0))],
)
def test_recovers_gravity_and_height_from_noisy_synthetic_depth(eye, target):
    T_true = look_at(eye, target)
    _, depth, _, K = render(BOXES, T_true)
    depth = add_noise(depth, np.random.default_rng(1))
    estimate = estimate_camera_pose(depth, K)
    assert gravity_error_deg(estimate.T_world_camera, T_true) < 0.5
    assert abs(estimate.T_world_camera[2, 3] - T_true[2, 3]) < 0.003
    assert estimate.inlier_fraction > 0.5
    n, d = estimate.plane_camera[:3], estimate.plane_camera[3]
    assert np.isclose(np.linalg.norm(n), 1.0) and d > 0


def test_world_frame_convention():
    T_true = look_at((-0.6, 0.2, 0.5), (0.0, 0.0, 0.0))
    _, depth, _, K = render([], T_true)
    T = estimate_camera_pose(depth, K).T_world_camera
    R = T[:3, :3]
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(T[:3, 3], [0.0, 0.0, 0.5], atol=1e-3)  # camera above the origin, table z = 0
    optical_axis_world = R[:, 2]
    assert optical_axis_world[0] > 0 and abs(optical_axis_world[1]) < 1e-9  # it looks along +x
    assert optical_axis_world[2] < 0  # and down
    # a table point seen by the camera lands on z = 0
    v, u = 240, 320
    p_camera = depth[v, u] * np.array([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], 1.0])
    assert abs((R @ p_camera + T[:3, 3])[2]) < 1e-3


def test_straight_down_view_takes_yaw_from_image_up():
    T = world_from_plane(np.array([0.0, 0.0, -1.0, 0.8]))
    assert np.allclose(T[:3, 3], [0, 0, 0.8])
    assert np.allclose(T[:3, :3] @ [0.0, -1.0, 0.0], [1.0, 0.0, 0.0])  # image up along +x


def test_picks_the_table_over_a_larger_floor():
    # far and high: the floor 0.75 m below fills most of the image around a small table
    T_true = look_at((-1.6, 0.0, 1.2), (0.0, 0.0, 0.0))
    _, depth, _, K = render(BOXES, T_true, table_levels=((0.0, 0.3),))
    depth = add_noise(depth, np.random.default_rng(2))
    estimate = estimate_camera_pose(depth, K)
    assert gravity_error_deg(estimate.T_world_camera, T_true) < 0.5
    assert abs(estimate.T_world_camera[2, 3] - 1.2) < 0.005  # the table, not the floor (1.95 m)


def test_too_few_valid_pixels():
    _, depth, _, K = render([], look_at((-0.6, 0.2, 0.5), (0, 0, 0)))
    depth[:, 2:] = 0.0  # 960 pixels left
    with pytest.raises(CameraPoseError, match="too few valid depth pixels"):
        estimate_camera_pose(depth, K)


def test_no_plane_in_random_depth():
    depth = np.random.default_rng(0).uniform(0.5, 3.0, (480, 640)).astype(np.float32)
    with pytest.raises(CameraPoseError, match="no plane"):
        estimate_camera_pose(depth, intrinsics())


def test_plane_above_the_camera():
    # under the floor looking up at it: a ceiling
    _, depth, _, K = render([], look_at((-1.0, 0.0, -1.5), (0.0, 0.0, -1.2)), table_levels=())
    with pytest.raises(CameraPoseError, match="faces down the image"):
        estimate_camera_pose(depth, K)


def test_camera_looking_up_past_the_table():
    K = intrinsics(640, 480, fovy_deg=120.0)
    _, depth, _, _ = render([], look_at((-0.8, 0.0, 0.1), (0.0, 0.0, 0.9)), K=K, table_levels=((0.0, 3.0),))
    with pytest.raises(CameraPoseError, match="not looking down"):
        estimate_camera_pose(depth, K)


def test_plane_inlier_fraction_tells_a_moved_camera():
    T_true = look_at((-0.6, 0.2, 0.5), (0.0, 0.0, 0.0))
    _, depth, _, K = render(BOXES, T_true)
    estimate = estimate_camera_pose(depth, K)
    assert plane_inlier_fraction(depth, K, estimate.plane_camera) == pytest.approx(estimate.inlier_fraction, abs=0.03)
    _, moved, _, _ = render(BOXES, look_at((-0.6, 0.3, 0.6), (0.0, 0.0, 0.0)))
    assert plane_inlier_fraction(moved, K, estimate.plane_camera) < 0.2


@pytest.fixture(scope="module")
def pool():
    return object_pool()


@pytest.mark.slow
@pytest.mark.parametrize("index", [0, 4, 8])
def test_simulator_frames_at_benchmark_poses(pool, index):
    scene, frame = render_benchmark_view(pool, np.random.default_rng([0, index]), (3, 10), with_visibility=False)
    T_true = frame.T_world_camera
    estimate = estimate_camera_pose(frame.depth_m, frame.K)
    assert gravity_error_deg(estimate.T_world_camera, T_true) < 1.0
    assert abs(estimate.T_world_camera[2, 3] - (T_true[2, 3] - scene.table_height_m)) < 0.005


def test_tracker_reuses_the_estimate_while_the_plane_fits():
    _, depth, _, K = render(BOXES, look_at((-0.6, 0.2, 0.5), (0.0, 0.0, 0.0)))
    tracker = CameraPoseTracker(max_reuse_frames=2)
    first = tracker.update(depth, K)
    assert tracker.update(depth, K) is first and tracker.update(depth, K) is first
    assert tracker.stats.reuses == 2 and tracker.stats.last_reused
    tracker.update(depth, K)  # at most max_reuse_frames in a row
    assert tracker.stats.estimates == 2 and not tracker.stats.last_reused
    T_moved = look_at((-0.6, 0.3, 0.6), (0.0, 0.0, 0.0))
    _, moved, _, _ = render(BOXES, T_moved)
    assert abs(tracker.update(moved, K).T_world_camera[2, 3] - 0.6) < 0.003
    assert tracker.stats.estimates == 3
    with pytest.raises(CameraPoseError, match="too few"):
        tracker.update(np.zeros_like(depth), K)
    assert tracker.last is None and tracker.stats.failures == 1 and "too few" in tracker.stats.last_error


@pytest.mark.parametrize(
    "plane, reason",
    [
        ((0.0, -0.8, -0.6, 0.5), ""),  # a table seen from 0.5 m, camera pitched down 37 deg
        ((0.1, -0.05, -0.99, 0.8), ""),  # straight down: any roll
        ((0.0, -0.8, -0.6, 0.01), "passes 1.0 cm from the camera"),
        ((0.0, -0.8, -0.6, 3.0), "farther than 2.0 m"),
        ((0.9, 0.1, -0.42, 1.0), "upright in the image"),  # a side wall
        ((0.0, 0.9, -0.44, 1.0), "faces down the image"),  # a ceiling
        ((0.0, -0.8, 0.6, 0.5), "not looking down"),
    ],
)
def test_plane_problem_reasons(plane, reason):
    plane = np.array(plane)
    plane[:3] /= np.linalg.norm(plane[:3])
    problem = plane_problem(plane, CameraPoseParams())
    assert (reason in problem) if reason else problem == ""


def test_picks_the_table_it_looks_at_over_a_higher_one_behind():
    T_true = look_at((-0.9, 0.0, 0.6), (0.1, 0.0, 0.0))
    second_table = Box((1.1, 0.0, 0.075), (0.45, 0.6, 0.075))  # its top 15 cm above the work table
    _, depth, _, K = render(BOXES, T_true, supports=[second_table])
    depth = add_noise(depth, np.random.default_rng(4))
    estimate = estimate_camera_pose(depth, K)
    assert gravity_error_deg(estimate.T_world_camera, T_true) < 0.5
    assert abs(estimate.T_world_camera[2, 3] - 0.6) < 0.005


def test_a_far_strip_and_outliers_do_not_outvote_a_table_filling_the_view():
    # a RealSense over a wooden table: the table fills the view, the top rows see a surface 2.6-3.1 m
    # away on a plane 13 deg steeper than the table (a wall's base seen through a thin strip can be fit
    # so), and some returns lie 10-17 m off
    T_true = look_at((-0.5, 0.0, 0.6), (0.2, 0.0, 0.0))
    _, depth, _, K = render(BOXES, T_true, table_levels=((0.0, 3.0),))
    rng = np.random.default_rng(5)
    depth = add_noise(depth, rng)
    rows = 40
    ray_y = (np.arange(rows)[:, None] - K[1, 2]) / K[1, 1]
    depth[:rows] = 0.745 / (0.573 + 0.819 * ray_y)  # the plane -0.819 y - 0.573 z + 0.745 = 0
    far = rng.random(depth.shape) < 0.01
    depth[far] = rng.uniform(10.0, 17.0, far.sum())
    estimate = estimate_camera_pose(depth, K)
    assert gravity_error_deg(estimate.T_world_camera, T_true) < 0.5
    assert abs(estimate.T_world_camera[2, 3] - 0.6) < 0.005
