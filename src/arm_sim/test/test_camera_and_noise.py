import numpy as np

from arm_core.camera import intrinsics, look_at, silhouette
from arm_sim.camera import sample_camera_pose
from arm_sim.depth_noise import DepthNoise, apply_depth_noise
from arm_sim.objects import ObjectModel, box
from arm_sim.scenes import PlacedObject, Scene
from arm_sim.world import SimWorld


def test_sampled_camera_poses_follow_the_benchmark_shell():
    rng = np.random.default_rng(0)
    for _ in range(50):
        T = sample_camera_pose(rng, (0.0, 0.0, 0.0))
        distance = np.linalg.norm(T[:3, 3])
        assert 0.125 - 1e-9 <= distance <= 1.5 + 1e-9 and T[2, 3] > 0


def test_silhouette_of_a_closed_box_matches_mujocos_rendering():
    part = box((0.1, 0.06, 0.08), (0.0, 0.0, 0.04))
    T = np.eye(4)
    T[:3, 3] = (0.05, 0.02, 0.0)
    scene = Scene([PlacedObject(ObjectModel("box", "box", part, [part]), 1.0, T)])
    world = SimWorld(scene, robot_arm=False)
    camera = look_at((0.5, 0.3, 0.4), (0.0, 0.0, 0.0))
    frame = world.render(camera)
    rendered = frame.labels == 1
    predicted = silhouette([part.vertices + T[:3, 3]], world.K, camera, 640, 480)
    overlap = (rendered & predicted).sum() / (rendered | predicted).sum()
    assert overlap > 0.97 and frame.visible_fraction[0] > 0.97


def test_depth_noise_grows_with_distance_and_drops_edges():
    K = intrinsics(640, 480, 45.0)
    rng = np.random.default_rng(0)
    near, far = np.full((480, 640), 0.5, np.float32), np.full((480, 640), 2.0, np.float32)
    noise = DepthNoise(random_dropout=0.0)
    err_near = np.std(apply_depth_noise(near, K, rng, noise)[near > 0] - 0.5)
    err_far = np.std(apply_depth_noise(far, K, rng, noise)[far > 0] - 2.0)
    assert err_far > 3 * err_near
    step = near.copy()
    step[:, 320:] = 1.0
    noisy = apply_depth_noise(step, K, rng, noise)
    assert (noisy[:, 318:322] == 0).mean() > 0.2 and (noisy[:, 100:200] == 0).mean() < 0.01
    assert np.array_equal(apply_depth_noise(step, K, rng, DepthNoise(enabled=False)), step)
    bad = step.copy()
    bad[0, :10] = np.nan
    bad[1, :10] = -1.0
    noisy_bad = apply_depth_noise(bad, K, rng, noise)
    assert np.all(np.isfinite(noisy_bad)) and np.all(noisy_bad >= 0)
