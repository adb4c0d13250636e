import numpy as np
import pytest
import torch

from arm_core.camera import look_at
from arm_core.frames import FrameInputError, validate_frame
from arm_reconstruction.checkpoint import CheckpointError, save_checkpoint
from arm_reconstruction.convex_parts import decomposition_iou
from arm_reconstruction.grid import GridInputError, voxelize_mesh
from arm_reconstruction.meshing import to_manifold
from arm_reconstruction.network import build_model
from arm_reconstruction.pipeline import (
    STAGES,
    ReconstructionPreempted,
    ReconstructionSettings,
    Reconstructor,
    reconstruct,
)
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene
from arm_sim.world import SimWorld

torch.set_num_threads(2)


@pytest.fixture(scope="module")
def sim():
    rng = np.random.default_rng(5)
    scene = cluttered_scene(object_pool(split="train", seed=0), rng, n_objects=6)
    world = SimWorld(scene, robot_arm=False, width=320, height=240)
    centre = np.mean([o.T_world_object[:3, 3] for o in scene.objects], axis=0)
    frame = world.render(look_at(centre + (0.55, 0.2, 0.45), centre), rng=rng)
    world.close()
    return scene, frame


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    """Checkpoints of freshly built (untrained) networks: the pipeline's plumbing, not its accuracy."""
    folder = tmp_path_factory.mktemp("checkpoints")
    torch.manual_seed(0)
    for variant in ("arm", "baseline"):
        save_checkpoint(folder / f"{variant}.pt", build_model(variant, 32), {}, {"note": "untrained"})
    return folder


def args(frame):
    return frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, frame.labels


def test_objects_the_network_leaves_empty_are_meshed_from_their_observed_voxels(sim, checkpoints):
    _, frame = sim
    reconstructor = Reconstructor(ReconstructionSettings(checkpoint_path=str(checkpoints / "arm.pt")))
    objects = reconstructor(*args(frame))
    visible_ids = sorted(int(i) for i in np.unique(frame.labels) if i > 0)
    assert [o.id for o in objects] == visible_ids
    grids = reconstructor.grids(frame.depth_m, frame.K, frame.T_world_camera, frame.labels)
    for obj in objects:  # an untrained network predicts ~0.1 everywhere: nothing above 0.5
        assert obj.ok and obj.from_observed_voxels and obj.grid is not None, obj.error
        observed = grids.grids[grids.object_ids.index(obj.id), 0] > 0.5
        centres = obj.grid.voxel_centers_world()[observed]
        lo, hi = obj.world_mesh().bounds
        assert np.all(centres >= lo - obj.grid.voxel_size_m) and np.all(centres <= hi + obj.grid.voxel_size_m)
    assert set(reconstructor.last_timings_s) == set(STAGES)
    assert reconstructor.last_timings_s["network"] > 0


def test_a_frame_asked_to_stop_is_abandoned_at_the_next_stage_and_the_next_frame_runs_whole(sim, checkpoints):
    _, frame = sim
    reconstructor = Reconstructor(ReconstructionSettings(checkpoint_path=str(checkpoints / "arm.pt")))
    checks = []

    def stop_at_the_third_check() -> bool:
        checks.append(dict(reconstructor.last_timings_s))
        return len(checks) == 3

    reconstructor.should_stop = stop_at_the_third_check
    with pytest.raises(ReconstructionPreempted):
        reconstructor(*args(frame))
    assert len(checks) == 3 and checks[-1]["network"] > 0 and checks[-1]["decomposition"] == 0
    assert reconstructor.last_timings_s["decomposition"] == 0
    objects = reconstructor(*args(frame))  # later checks say go on
    assert len(checks) > 3 and objects and all(o.ok for o in objects)


def test_objects_from_ground_truth_occupancy_are_simulation_ready(sim, checkpoints):
    scene, frame = sim
    reconstructor = Reconstructor(ReconstructionSettings(checkpoint_path=str(checkpoints / "arm.pt")))
    grids = reconstructor.grids(frame.depth_m, frame.K, frame.T_world_camera, frame.labels)
    pairs = zip(grids.object_ids, grids.frames, strict=True)
    truth = np.stack([voxelize_mesh(scene.objects[i - 1].world_mesh(), f) for i, f in pairs]).astype(np.float32)
    objects = reconstructor.build_objects(grids, truth, frame.depth_m, frame.labels, frame.K, frame.T_world_camera)
    assert all(o.ok for o in objects)
    solids, fidelity = [], []
    for obj in objects:
        assert obj.mesh.is_watertight and obj.mesh.volume > 0
        np.testing.assert_allclose(obj.mesh.center_mass, 0.0, atol=1e-6)
        np.testing.assert_allclose(obj.T_world_object[:3, :3], np.eye(3))
        world = obj.world_mesh()
        lo = np.asarray(obj.grid.origin_world)
        assert np.all(world.bounds[0] >= lo - 1e-6) and np.all(world.bounds[1] <= lo + obj.grid.side_m + 1e-6)
        assert 1 <= len(obj.convex_parts) <= 8 and all(len(p.vertices) <= 64 for p in obj.convex_parts)
        fidelity.append(decomposition_iou(obj.mesh, obj.convex_parts))
        true_visible = frame.visible_fraction[obj.id - 1]
        assert 0 <= obj.visible_fraction <= 1 and abs(obj.visible_fraction - true_visible) < 0.35
        solids.append(to_manifold(world))
    # A thin-walled cup, its seen footprint ring added to the voxelized truth, is the hardest (0.88).
    assert min(fidelity) >= 0.85 and np.mean(fidelity) >= 0.9, fidelity
    for a in range(len(solids)):
        for b in range(a + 1, len(solids)):
            assert (solids[a] ^ solids[b]).volume() < 1e-9, "meshes must not intersect"


def test_method_variants_post_process_the_network_output(sim, checkpoints):
    _, frame = sim
    path = str(checkpoints / "baseline.pt")
    plain = Reconstructor(ReconstructionSettings(method="baseline", checkpoint_path=path))
    grids = plain.grids(frame.depth_m, frame.K, frame.T_world_camera, frame.labels)
    raw = plain.predict(grids)
    carving = Reconstructor(ReconstructionSettings(method="baseline+ray carving", checkpoint_path=path))
    carved = carving.predict(grids)
    observed_empty = grids.grids[:, 2] > 0
    assert observed_empty.any() and np.all(carved[observed_empty] == 0)
    np.testing.assert_allclose(carved[~observed_empty], raw[~observed_empty], atol=1e-6)
    extruded = Reconstructor(ReconstructionSettings(method="baseline+E", checkpoint_path=path)).predict(grids)
    assert np.all(np.diff(extruded, axis=3) <= 0) and np.all(extruded >= raw - 1e-6)


def test_bad_frames_and_objects(sim, checkpoints):
    _, frame = sim
    reconstructor = Reconstructor(ReconstructionSettings(checkpoint_path=str(checkpoints / "arm.pt")))
    rgb, depth, K, T, labels = args(frame)
    bad_pose = T.copy()
    bad_pose[2, 3] = np.nan
    with pytest.raises(FrameInputError):
        reconstructor(rgb, depth, K, bad_pose, labels)
    with pytest.raises(GridInputError, match="rgb"):
        reconstructor(rgb[:10], depth, K, T, labels)
    assert reconstructor(rgb, depth, K, T, np.zeros_like(labels)) == []
    single = np.zeros_like(labels)
    single[100, 100] = 7
    (obj,) = reconstructor(None, depth, K, T, single)
    assert obj.id == 7 and not obj.ok and "valid depth points" in obj.error and len(obj.mesh.faces) == 0


def test_every_stage_sees_the_checked_depth(sim, checkpoints):
    """Non-finite depth and lone wrong returns (a sensor's speckles) inside an object give the same
    objects as the frame the validator cleans them from: no stage reads the raw depth."""
    _, frame = sim
    reconstructor = Reconstructor(ReconstructionSettings(checkpoint_path=str(checkpoints / "arm.pt")))
    rgb, depth, K, T, labels = args(frame)
    raw = depth.copy()
    ys, xs = np.nonzero(labels > 0)
    pick = np.random.default_rng(2).choice(len(ys), size=12, replace=False)
    raw[ys[pick[:6]], xs[pick[:6]]] = np.nan
    raw[ys[pick[6:]], xs[pick[6:]]] = 17.0  # single returns far behind the surface around them
    cleaned = validate_frame(raw, K, T).depth_m
    assert np.all(cleaned[ys[pick[:6]], xs[pick[:6]]] == 0.0) and np.any(cleaned[ys[pick[6:]], xs[pick[6:]]] == 0.0)
    from_raw = reconstructor(rgb, raw, K, T, labels)
    from_cleaned = reconstructor(rgb, cleaned, K, T, labels)
    assert [o.id for o in from_raw] == [o.id for o in from_cleaned] and from_raw
    for a, b in zip(from_raw, from_cleaned, strict=True):
        assert a.ok == b.ok and np.array_equal(a.T_world_object, b.T_world_object)
        assert np.array_equal(a.mesh.vertices, b.mesh.vertices) and np.array_equal(a.vertex_colours, b.vertex_colours)


def test_checkpoint_problems_are_clear_errors(checkpoints, tmp_path):
    with pytest.raises(CheckpointError, match="variant 'baseline', expected 'arm'"):
        Reconstructor(ReconstructionSettings(method="arm", checkpoint_path=str(checkpoints / "baseline.pt")))
    with pytest.raises(CheckpointError, match="resolution 32, expected 64"):
        Reconstructor(ReconstructionSettings(checkpoint_path=str(checkpoints / "arm.pt"), resolution=64))
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes((checkpoints / "arm.pt").read_bytes()[:1000])
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        Reconstructor(ReconstructionSettings(checkpoint_path=str(corrupt)))
    with pytest.raises(CheckpointError, match="no checkpoint"):
        Reconstructor(ReconstructionSettings(checkpoint_path=str(tmp_path / "none.pt")))
    with pytest.raises(ValueError, match="unknown reconstruction method"):
        ReconstructionSettings(method="genre")


def test_one_call_api(sim, checkpoints):
    _, frame = sim
    objects = reconstruct(*args(frame), method="arm", checkpoint_path=str(checkpoints / "arm.pt"), threshold=0.5)
    assert len(objects) == len([i for i in np.unique(frame.labels) if i > 0])
