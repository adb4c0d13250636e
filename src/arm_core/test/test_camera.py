import numpy as np

from arm_core.camera import (
    backproject_image,
    backproject_pixels,
    intrinsics,
    look_at,
    project_points,
    ray_directions_world,
    transform_points,
    world_height,
)

K = intrinsics(64, 48, 45.0)
T_WORLD_CAMERA = look_at((0.8, 0.2, 0.6), (0.0, 0.0, 0.0))


def _depth_image():
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 2.0, (48, 64)).astype(np.float32)
    depth[rng.random((48, 64)) < 0.1] = 0.0
    return depth


def test_look_at_builds_an_optical_frame():
    T = look_at((1.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3))
    assert np.allclose(T[:3, 2], np.array([-1, 0, -1]) / np.sqrt(2))  # z forward
    assert T[2, 1] < 0  # image y (down) points down in the world


def test_projecting_backprojected_depth_gives_back_the_pixels():
    depth = _depth_image()
    v, u = np.nonzero(depth > 0)
    points_world = backproject_pixels(depth, v, u, K, T_WORLD_CAMERA)
    uv, z = project_points(points_world, K, T_WORLD_CAMERA)
    assert np.allclose(uv, np.stack([u, v], 1), atol=1e-9)
    assert np.allclose(z, depth[v, u], rtol=1e-6)


def test_organized_and_per_pixel_backprojection_agree():
    depth = _depth_image()
    points_camera = backproject_image(depth, K)
    assert points_camera.dtype == np.float32 and points_camera.shape == (48, 64, 3)
    assert np.all(points_camera[depth == 0] == 0)
    v, u = np.nonzero(depth > 0)
    camera_points = backproject_pixels(depth, v, u, K, np.eye(4))
    assert np.allclose(points_camera[v, u], camera_points, atol=1e-5)
    points_world = transform_points(points_camera, T_WORLD_CAMERA)
    assert points_world.dtype == np.float32
    assert np.allclose(points_world[v, u], backproject_pixels(depth, v, u, K, T_WORLD_CAMERA), atol=1e-5)
    assert np.allclose(world_height(depth, K, T_WORLD_CAMERA)[v, u], points_world[v, u, 2], atol=1e-5)


def test_ray_directions_reach_the_backprojected_points():
    depth = _depth_image()
    v, u = np.nonzero(depth > 0)
    directions = ray_directions_world(v, u, K, T_WORLD_CAMERA)
    reached = T_WORLD_CAMERA[:3, 3] + directions * depth[v, u, None]
    assert np.allclose(reached, backproject_pixels(depth, v, u, K, T_WORLD_CAMERA), atol=1e-5)
