import json
import shutil
import subprocess
from dataclasses import replace

import cv2
import mujoco
import numpy as np
import pytest
import torch
import trimesh

from arm_core.camera import look_at
from arm_core.frames import FrameInputError
from arm_offline.inputs import find_frames, load_camera, load_frame, load_poses
from arm_offline.reconstruct_frames import SUMMARY_FILE, FrameReconstructor, OfflineSettings, main, reconstruct_folder
from arm_reconstruction.pipeline import ReconstructionSettings, Reconstructor
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene
from arm_sim.world import SimWorld

torch.set_num_threads(2)
WIDTH, HEIGHT = 320, 240
VIEW_OFFSETS_M = ((0.35, 0.15, 0.55), (-0.1, 0.4, 0.55))


def write_frame(folder, name, rgb, depth_m, flat=False):
    colour = folder / f"rgb_{name}.png" if flat else folder / "color" / f"{name}.png"
    depth = folder / f"depth_{name}.png" if flat else folder / "depth" / f"{name}.png"
    for path in (colour, depth):
        path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(colour), rgb[..., ::-1])
    cv2.imwrite(str(depth), np.round(depth_m * 1000.0).astype(np.uint16))


@pytest.fixture(scope="module")
def frames_folder(tmp_path_factory):
    """Two rendered frames of one 3-object scene (one in the flat rgb_/depth_ layout) with poses and
    intrinsics; plus a corrupt colour PNG and a colour image without depth."""
    folder = tmp_path_factory.mktemp("frames")
    rng = np.random.default_rng(3)
    pool = object_pool(split="train", seed=0)  # plain domain: the command is under test, not segmentation quality
    scene = cluttered_scene(pool, rng, n_objects=3, scale_range=(1.0, 1.5), domain="plain")
    world = SimWorld(scene, robot_arm=False, width=WIDTH, height=HEIGHT)
    centre = np.mean([o.T_world_object[:3, 3] for o in scene.objects], axis=0)
    poses, visible = {}, {}
    for i, offset in enumerate(VIEW_OFFSETS_M):
        T = look_at(centre + offset, centre)
        frame = world.render(T, rng=rng)
        name = f"{i:06d}"
        write_frame(folder, name, frame.rgb, frame.depth_m, flat=i == 1)
        poses[name] = T.tolist()
        visible[name] = len(np.unique(frame.labels)) - 1
    world.close()
    K = world.K
    intrinsics = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "width": WIDTH, "height": HEIGHT}
    (folder / "intrinsics.json").write_text(json.dumps(intrinsics))
    (folder / "poses.json").write_text(json.dumps(poses))
    shutil.copy(folder / "depth" / "000000.png", folder / "depth" / "000002.png")
    (folder / "color" / "000002.png").write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    shutil.copy(folder / "color" / "000000.png", folder / "color" / "000003.png")
    return folder, visible


@pytest.fixture(scope="module")
def reconstructor():
    return Reconstructor(ReconstructionSettings())


def test_frames_are_reconstructed_into_meshes_and_a_loadable_scene(frames_folder, reconstructor, tmp_path):
    folder, visible = frames_folder
    summary = reconstruct_folder(folder, tmp_path, OfflineSettings(), reconstructor=reconstructor)
    assert json.loads((tmp_path / SUMMARY_FILE).read_text()) == json.loads(json.dumps(summary))
    entries = {entry["frame"]: entry for entry in summary["frames"]}
    assert sorted(entries) == ["000000", "000001", "000002", "000003"]
    assert (summary["n_ok"], summary["n_failed"]) == (2, 2)
    assert "000002.png" in entries["000002"]["error"] and "decode" in entries["000002"]["error"]
    assert "000003.png: no depth image" in entries["000003"]["error"]
    for name, true_count in visible.items():
        entry = entries[name]
        assert entry["ok"] and entry["pose_source"] == "given", entry["error"]
        assert abs(entry["n_reconstructed"] - true_count) <= 1
        out = tmp_path / name
        assert cv2.imread(str(out / entry["overlay"])).shape == (HEIGHT, WIDTH, 3)
        model = mujoco.MjModel.from_xml_path(str(out / entry["scene"]))
        bodies = [o["body"] for o in entry["objects"] if o["ok"]]
        assert len(bodies) == entry["n_reconstructed"] and all(model.body(b).id > 0 for b in bodies)
        assert model.ngeom == 2 + sum(len(o["convex_parts"]) for o in entry["objects"] if o["ok"])
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        start_m = data.xpos[1:].copy()
        mujoco.mj_step(model, data, nstep=250)  # 0.5 s: the objects rest on the table
        assert np.abs(data.xpos[1:] - start_m).max() < 0.02
        for obj in entry["objects"]:
            mesh = trimesh.load(out / obj["mesh"], force="mesh")
            assert mesh.is_watertight and mesh.volume > 0
            # coloured from the camera image: not the exporter's default grey everywhere
            assert mesh.visual.kind == "vertex" and len(np.unique(mesh.visual.vertex_colors[:, :3], axis=0)) > 1
            np.testing.assert_allclose(mesh.extents, obj["extents_m"], atol=1e-4)
            for part in obj["convex_parts"]:
                part = trimesh.load(out / part, force="mesh")
                assert part.volume == pytest.approx(part.convex_hull.volume, rel=1e-3)
        assert set(entry["timings_s"]) >= {"load", "pose", "segmentation", "reconstruction", "export", "total"}


def test_finished_frames_are_skipped_unless_overwrite(frames_folder, reconstructor, tmp_path):
    folder, _ = frames_folder
    reconstruct_folder(folder, tmp_path, OfflineSettings(), reconstructor=reconstructor)
    again = reconstruct_folder(folder, tmp_path, OfflineSettings(), reconstructor=reconstructor)
    assert [f["skipped"] for f in again["frames"]] == [True, True, False, False]
    settings = OfflineSettings(mesh_format="obj", overwrite=True)
    redo = reconstruct_folder(folder, tmp_path, settings, reconstructor=reconstructor)
    assert redo["n_skipped"] == 0 and redo["n_ok"] == 2
    assert not list((tmp_path / "000000").glob("*.ply")) and list((tmp_path / "000000").glob("object_*.obj"))


def test_console_script_exit_status(frames_folder, tmp_path):
    folder, _ = frames_folder
    command = ["reconstruct_frames", "--input", str(folder), "--output", str(tmp_path / "out"), "--mesh-format", "glb"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "000002.png" in run.stderr and "000003.png: no depth image" in run.stderr
    glb = sorted((tmp_path / "out" / "000001").glob("object_*.glb"))
    assert glb and trimesh.load(glb[0], force="mesh").visual.kind == "vertex", "GLB keeps the vertex colours"
    with pytest.raises(SystemExit) as exit_info:
        main(["--input", str(tmp_path / "missing"), "--output", str(tmp_path / "o")])
    assert exit_info.value.code == 2
    with pytest.raises(SystemExit) as exit_info:
        main(["--input", str(folder), "--output", str(tmp_path / "o"), "--depth-scale", "0"])
    assert exit_info.value.code == 2
    broken = tmp_path / "broken"
    (broken / "color").mkdir(parents=True)
    shutil.copy(folder / "intrinsics.json", broken)
    shutil.copy(folder / "color" / "000000.png", broken / "color")
    assert main(["--input", str(broken), "--output", str(tmp_path / "o"), "--no-progress"]) == 1


def test_camera_info_yaml_and_bad_intrinsics(tmp_path):
    info = tmp_path / "camera_info.yaml"
    info.write_text(
        "image_width: 320\nimage_height: 240\ncamera_name: cam\n"
        "camera_matrix: {rows: 3, cols: 3, data: [290.0, 0.0, 160.5, 0.0, 291.0, 120.5, 0.0, 0.0, 1.0]}\n"
        "distortion_model: plumb_bob\ndistortion_coefficients: {rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}\n"
    )
    camera = load_camera(info)
    np.testing.assert_allclose(camera.K, [[290.0, 0, 160.5], [0, 291.0, 120.5], [0, 0, 1]])
    assert (camera.width, camera.height, camera.distortion_model) == (320, 240, "plumb_bob")
    assert camera.distortion == (0,) * 5
    info.write_text(info.read_text().replace("[0, 0, 0, 0, 0]", "[0.1, -0.2, 0, 0, 0]"))
    assert load_camera(info).distortion == (0.1, -0.2, 0, 0, 0)
    bad = tmp_path / "intrinsics.json"
    bad.write_text(json.dumps({"fx": -1, "fy": 300, "cx": 160, "cy": 120, "width": 320, "height": 240}))
    with pytest.raises(FrameInputError, match="invalid intrinsics"):
        load_camera(bad)
    bad.write_text(json.dumps({"fx": 300}))
    with pytest.raises(FrameInputError, match="missing fy, cx, cy, width, height"):
        load_camera(bad)
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps({"a": np.diag([2.0, 1, 1, 1]).tolist()}))
    with pytest.raises(FrameInputError, match="'a' is not a rigid"):
        load_poses(poses)


def test_poses_are_estimated_when_not_given(frames_folder, reconstructor, tmp_path):
    folder, visible = frames_folder
    given = reconstruct_folder(folder, tmp_path / "given", OfflineSettings(), reconstructor=reconstructor)
    unposed = tmp_path / "unposed"
    shutil.copytree(folder, unposed, ignore=shutil.ignore_patterns("poses.json", "*00000[23].png"))
    estimated = reconstruct_folder(unposed, tmp_path / "estimated", OfflineSettings(), reconstructor=reconstructor)
    assert estimated["n_ok"] == len(visible)
    for with_pose, entry in zip(given["frames"], estimated["frames"], strict=False):
        assert entry["pose_source"] == "estimated" and entry["pose_inlier_fraction"] > 0.3
        assert abs(entry["n_reconstructed"] - visible[entry["frame"]]) <= 1
        assert abs(entry["table_height_m"]) < 0.01  # the estimate's world has the table top at z = 0
        heights = sorted(o["extents_m"][2] for o in entry["objects"] if o["ok"])
        true_heights = sorted(o["extents_m"][2] for o in with_pose["objects"] if o["ok"])
        if len(heights) == len(true_heights):
            np.testing.assert_allclose(heights, true_heights, rtol=0.2, atol=0.01)  # grids differ in yaw
        mujoco.MjModel.from_xml_path(str(tmp_path / "estimated" / entry["frame"] / entry["scene"]))


def test_distorted_images_are_undistorted_and_unknown_models_refused(frames_folder, reconstructor, tmp_path):
    folder, _ = frames_folder
    camera = load_camera(folder / "intrinsics.json")
    process = FrameReconstructor(OfflineSettings(), reconstructor)
    files, pose = find_frames(folder)[0], np.array(json.loads((folder / "poses.json").read_text())["000000"])
    plumb_bob = process(files, replace(camera, distortion_model="plumb_bob", distortion=(0.05, 0, 0, 0, 0)), pose,
                        tmp_path / "plumb_bob")  # fmt: skip
    unknown = process(files, replace(camera, distortion_model="mystery", distortion=(0.1,)), pose, tmp_path / "u")
    assert not unknown["ok"] and "intrinsics.json" in unknown["error"] and "mystery [0.1]" in unknown["error"]
    assert plumb_bob["ok"], plumb_bob["error"]


def test_depth_dtype_and_size_mismatch_are_named(frames_folder, tmp_path):
    folder, _ = frames_folder
    camera = load_camera(folder / "intrinsics.json")
    rgb = cv2.imread(str(folder / "color" / "000000.png"))[..., ::-1]
    (tmp_path / "color").mkdir()
    (tmp_path / "depth").mkdir()
    cv2.imwrite(str(tmp_path / "color" / "a.png"), rgb[..., ::-1])
    cv2.imwrite(str(tmp_path / "depth" / "a.png"), np.zeros((HEIGHT, WIDTH), np.uint8))
    cv2.imwrite(str(tmp_path / "color" / "b.jpg"), rgb[:200, :, ::-1])
    cv2.imwrite(str(tmp_path / "depth" / "b.png"), np.zeros((HEIGHT, WIDTH), np.uint16))
    a, b = find_frames(tmp_path)
    with pytest.raises(FrameInputError, match="a.png: depth must be a single-channel 16-bit PNG, got uint8"):
        load_frame(a, camera, 0.001)
    with pytest.raises(FrameInputError, match="b.jpg is 320x200 but depth .*b.png is 320x240"):
        load_frame(b, camera, 0.001)
