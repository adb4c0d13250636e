import json
import pathlib

import cv2
import numpy as np
import pytest

from arm_benchmarks.bench_real import main, on_support_share, perturbed_depth
from arm_core.camera import look_at
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene
from arm_sim.world import SimWorld

SHARED_REAL = pathlib.Path(__file__).resolve().parents[3] / ".." / "shared" / "real"


@pytest.fixture(scope="module")
def labelled_folder(tmp_path_factory):
    """One rendered 320x240 frame of a 3-object scene in the reconstruct_frames layout, with its
    true instance labels and no pose (the benchmark estimates it)."""
    folder = tmp_path_factory.mktemp("real_layout")
    rng = np.random.default_rng(4)
    pool = object_pool(split="train", seed=0)
    scene = cluttered_scene(pool, rng, n_objects=3, scale_range=(1.0, 1.4), domain="plain")
    world = SimWorld(scene, robot_arm=False, width=320, height=240)
    centre = np.mean([o.T_world_object[:3, 3] for o in scene.objects], axis=0)
    frame = world.render(look_at(centre + (0.4, 0.1, 0.5), centre), rng=rng)
    world.close()
    for sub, image in (("color", frame.rgb[..., ::-1]), ("depth", np.round(frame.depth_m * 1000).astype(np.uint16)),
                       ("labels", frame.labels.astype(np.uint16))):  # fmt: skip
        (folder / sub).mkdir()
        cv2.imwrite(str(folder / sub / "000000.png"), image)
    K = frame.K
    intrinsics = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "width": 320, "height": 240}
    (folder / "intrinsics.json").write_text(json.dumps(intrinsics))
    return folder


def test_perturbed_depth_keeps_missing_returns_missing():
    depth = np.full((120, 160), 0.8, np.float32)
    depth[:, :20] = 0.0
    K = np.array([[150.0, 0, 80], [0, 150.0, 60], [0, 0, 1]])
    noisy = perturbed_depth(depth, K, np.random.default_rng(0))
    assert np.all(noisy[:, :20] == 0.0)
    kept = noisy[:, 30:] > 0
    assert kept.mean() > 0.95 and np.abs(noisy[:, 30:][kept] - 0.8).max() < 0.02
    assert np.allclose(noisy * 1000, np.round(noisy * 1000), atol=1e-3), "whole millimetres, as a sensor encodes"


def test_on_support_share_counts_instance_pixels_on_the_table_plane():
    K = np.array([[100.0, 0, 20], [0, 100.0, 15], [0, 0, 1]])
    T_world_camera = np.array([[1.0, 0, 0, 0], [0, -1.0, 0, 0], [0, 0, -1.0, 1.0], [0, 0, 0, 1.0]])  # 1 m above, down
    depth = np.ones((30, 40), np.float32)
    depth[10:20, 10:20] = 0.9  # a box 10 cm high
    labels = np.zeros((30, 40), np.uint16)
    labels[10:20, 10:20] = 1
    assert on_support_share(labels, depth, K, T_world_camera) == 0.0
    labels[10:20, 20:30] = 1  # as much table beside it taken for the box
    assert on_support_share(labels, depth, K, T_world_camera) == 0.5
    assert on_support_share(np.zeros_like(labels), depth, K, T_world_camera) is None


def test_reports_support_scene_physics_metrics_and_noise_and_resumes(labelled_folder, tmp_path):
    out = tmp_path / "real"
    args = [str(labelled_folder), "--out", str(out), "--noise-copies", "2", "--physics-s", "0.5"]
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    totals = summary["sets"][labelled_folder.name]
    assert totals["frames"] == 1 and totals["support_found"] == 1 and not totals["failed_frames"]
    assert totals["instances"] >= 2 and totals["objects_simulated"] >= 2
    assert 0.0 <= totals["stable_fraction"] <= 1.0 and totals["noise"]["frames"] == 1
    assert 0.0 <= totals["on_support_share"] < 0.2
    assert totals["metrics"]["overlap_f"] > 0.5 and totals["metrics"]["frames"] == 1
    variants = totals["camera_variants"]
    assert set(variants) == {"zoom_1.7x", "640x480", "160x120", "speckles"}
    assert all(v["frames"] == 1 and "overlap_f" in v["metrics"] for v in variants.values())
    assert variants["speckles"]["support_found"] == 1 and variants["640x480"]["support_found"] == 1
    row = summary["frames"][labelled_folder.name][0]
    assert abs(row["normal_camera"][1]) > 0.3 and row["camera_height_m"] > 0.3
    assert (out / row["sheet"]).is_file() and "| 000000 |" in (out / "report.md").read_text()
    cache = out / labelled_folder.name / "frames" / "000000" / "bench.json"
    stamp = cache.stat().st_mtime_ns
    assert main(args) == 0 and cache.stat().st_mtime_ns == stamp, "a benchmarked frame is not redone"


@pytest.mark.skipif(not (SHARED_REAL / "ycb_tables").is_dir(), reason="needs ../shared/real (not in a user's clone)")
def test_a_realsense_table_filling_the_view_is_found(tmp_path):
    out = tmp_path / "real"
    assert main([str(SHARED_REAL / "ycb_tables"), "--out", str(out), "--max-frames", "1", "--noise-copies", "1"]) == 0
    row = json.loads((out / "summary.json").read_text())["frames"]["ycb_tables"][0]
    assert row["ok"] and 0.5 < row["camera_height_m"] < 0.7 and row["inlier_fraction"] > 0.4
    assert 4 <= row["instances"] <= 8
