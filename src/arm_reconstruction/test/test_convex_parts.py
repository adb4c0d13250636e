import numpy as np
import pytest
import trimesh

from arm_reconstruction.convex_parts import (
    ConvexDecomposer,
    DecompositionSettings,
    cap_vertices,
    decomposition_iou,
)
from arm_reconstruction.grid import GridFrame, voxelize_mesh
from arm_reconstruction.meshing import occupancy_mesh
from arm_sim.objects import object_pool


@pytest.fixture(scope="module")
def reconstructed_shapes():
    """Marching-cubes meshes of real library objects voxelized in 32^3 grids of side 4 * extent."""
    pool = object_pool(split="train", seed=0)
    meshes = []
    for model in pool.models[:8]:
        mesh = model.mesh.copy()
        mesh.apply_scale(0.08 / max(mesh.extents))
        side = 4 * float(np.linalg.norm(mesh.extents))
        centre = mesh.bounds.mean(0)
        frame = GridFrame(np.array([centre[0] - side / 2, centre[1] - side / 2, 0.0]), side / 32, 32, 0.0)
        occupancy = voxelize_mesh(mesh, frame)
        meshes.append(occupancy_mesh(occupancy.astype(np.float32), frame))
    return meshes


def l_shape():
    a = trimesh.creation.box((0.1, 0.02, 0.02)).apply_translation((0.05, 0.01, 0.01))
    b = trimesh.creation.box((0.02, 0.1, 0.02)).apply_translation((0.01, 0.05, 0.01))
    return trimesh.boolean.union([a, b], engine="manifold")


def test_decomposition_is_faithful_and_simulation_ready(reconstructed_shapes):
    decompose = ConvexDecomposer(DecompositionSettings(max_parts=8, max_vertices=64))
    for mesh in reconstructed_shapes:
        parts = decompose(mesh)
        assert 1 <= len(parts) <= 8
        for part in parts:
            assert len(part.vertices) <= 64 and part.is_watertight and part.is_convex and part.volume > 0
        assert decomposition_iou(mesh, parts) >= 0.9


def test_concave_shape_is_split():
    mesh = l_shape()
    parts = ConvexDecomposer()(mesh)
    assert len(parts) >= 2
    assert decomposition_iou(mesh, parts) > 0.97
    single = ConvexDecomposer(DecompositionSettings(method="hull"))(mesh)
    assert len(single) == 1 and decomposition_iou(mesh, single) < 0.7


def test_caps_cache_and_degenerate_meshes():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
    decompose = ConvexDecomposer(DecompositionSettings(max_vertices=32))
    parts = decompose(sphere)
    assert len(parts) == 1 and len(parts[0].vertices) <= 32
    assert decomposition_iou(sphere, parts) > 0.8
    again = decompose(sphere)
    assert decompose.cache_hits == 1 and np.allclose(again[0].vertices, parts[0].vertices)
    assert decompose(trimesh.Trimesh()) == []
    open_box = trimesh.creation.box((0.1, 0.1, 0.1))
    open_box.update_faces(np.arange(len(open_box.faces)) > 1)
    parts = decompose(open_box)
    assert len(parts) == 1 and parts[0].volume == pytest.approx(0.001, rel=1e-6)
    points = np.random.default_rng(0).normal(size=(500, 3))
    assert len(cap_vertices(points, 64)) <= 64


def test_coacd_backend_runs_with_caps():
    parts = ConvexDecomposer(DecompositionSettings(method="coacd", max_parts=4, max_vertices=32))(l_shape())
    assert 1 <= len(parts) <= 4 and all(len(p.vertices) <= 32 for p in parts)


def test_settings_are_validated():
    with pytest.raises(ValueError, match="max_parts"):
        DecompositionSettings(max_parts=0)
    with pytest.raises(ValueError, match="max_vertices"):
        DecompositionSettings(max_vertices=3)
    with pytest.raises(ValueError, match="unknown decomposition method"):
        DecompositionSettings(method="vhacd")
