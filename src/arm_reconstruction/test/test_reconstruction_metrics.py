import numpy as np
import pytest
import trimesh

from arm_reconstruction.grid import GridFrame
from arm_reconstruction.metrics import (
    chamfer_distance_m,
    enclosing_grid,
    is_closed,
    normal_consistency,
    sample_surface_points,
    volumetric_iou,
)


def box(extents, centre=(0.0, 0.0, 0.0)):
    return trimesh.creation.box(extents=extents).apply_translation(centre)


def test_surface_samples_lie_on_the_surface_spread_by_area():
    mesh = box((0.2, 0.1, 0.1))
    points = sample_surface_points(mesh, 20000, seed=3)
    half = np.array([0.1, 0.05, 0.05])
    on_face = np.isclose(np.abs(points), half, atol=1e-9)
    assert np.all(on_face.any(axis=1)) and np.all(np.abs(points) <= half + 1e-9)
    # face areas: x-faces 2 * 0.01, y- and z-faces 2 * 0.02 each -> fractions 0.2, 0.4, 0.4
    fractions = on_face.mean(axis=0)
    np.testing.assert_allclose(fractions, [0.2, 0.4, 0.4], atol=0.02)
    np.testing.assert_array_equal(points, sample_surface_points(mesh, 20000, seed=3))


def test_chamfer_is_zero_for_identical_meshes_and_symmetric():
    a = trimesh.creation.icosphere(3, radius=0.05)
    b = box((0.08, 0.05, 0.12), (0.01, 0.0, 0.0))
    assert chamfer_distance_m(a, a) == 0.0
    assert chamfer_distance_m(a, b, samples=2000) == chamfer_distance_m(b, a, samples=2000)


def test_chamfer_of_concentric_spheres_is_the_radius_gap():
    inner = trimesh.creation.icosphere(4, radius=0.05)
    outer = trimesh.creation.icosphere(4, radius=0.07)
    assert chamfer_distance_m(inner, outer, samples=8000) == pytest.approx(0.02, rel=0.08)


def test_chamfer_grows_with_translation():
    mesh = box((0.05, 0.05, 0.05))
    shifted = [chamfer_distance_m(mesh, mesh.copy().apply_translation((dx, 0, 0))) for dx in (0.0, 0.01, 0.05, 0.2)]
    assert shifted[0] == 0.0 and np.all(np.diff(shifted) > 0)
    assert 0.15 < shifted[-1] < 0.2  # nearest faces 0.15 m apart, farthest 0.2 m


def test_chamfer_rejects_empty_meshes():
    with pytest.raises(ValueError, match="without faces"):
        chamfer_distance_m(box((0.1, 0.1, 0.1)), trimesh.Trimesh())


def test_volumetric_iou_of_overlapping_boxes():
    a = box((0.2, 0.1, 0.1), (0.1, 0.0, 0.0))
    b = box((0.2, 0.1, 0.1), (0.2, 0.0, 0.0))
    assert volumetric_iou(a, a) == 1.0
    assert volumetric_iou(a, b, resolution=64) == pytest.approx(1 / 3, abs=0.02)
    assert volumetric_iou(a, box((0.1, 0.1, 0.1), (1.0, 0.0, 0.0))) == 0.0
    assert volumetric_iou(a, trimesh.Trimesh()) == 0.0


def test_surfaces_touching_along_an_edge_are_closed_and_measured():
    a = box((0.1, 0.1, 0.1), (0.05, 0.05, 0.05))
    b = box((0.1, 0.1, 0.1), (0.15, 0.15, 0.05))
    touching = trimesh.Trimesh(np.vstack([a.vertices, b.vertices]), np.vstack([a.faces, b.faces + 8]), process=True)
    assert not touching.is_watertight and is_closed(touching) and len(touching.vertices) == 14
    assert volumetric_iou(touching, a, resolution=64) == pytest.approx(0.5, abs=0.03)


def test_volumetric_iou_in_a_given_frame_and_errors():
    a = box((0.1, 0.1, 0.1), (0.05, 0.05, 0.05))
    frame = GridFrame(np.zeros(3), 0.2 / 32, 32, 0.0)
    assert volumetric_iou(a, a, frame=frame) == 1.0
    enclosing = enclosing_grid([a, box((0.1, 0.1, 0.1), (0.5, 0.0, 0.0))], 32)
    assert enclosing.side_m > 0.55
    open_mesh = box((0.1, 0.1, 0.1))
    open_mesh.update_faces(np.arange(len(open_mesh.faces)) > 0)
    with pytest.raises(ValueError, match="not a closed surface"):
        volumetric_iou(a, open_mesh)
    with pytest.raises(ValueError, match="both meshes are empty"):
        volumetric_iou(trimesh.Trimesh(), trimesh.Trimesh())


def test_normal_consistency_is_one_for_the_same_surface_and_low_for_a_blob():
    box = trimesh.creation.box((0.08, 0.08, 0.08))
    assert normal_consistency(box, box) > 0.99
    blob = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    score = normal_consistency(blob, box)
    assert 0.5 < score < 0.95  # a sphere's normals agree with a box's only near the face centres
    shifted = box.copy()
    shifted.apply_translation((0.002, 0.0, 0.0))  # a small shift keeps the normals, except along the edges
    assert normal_consistency(shifted, box) > 0.95 and chamfer_distance_m(shifted, box) > 0.0003
