import numpy as np
import trimesh

from arm_reconstruction.grid import GridFrame
from arm_reconstruction.metrics import chamfer_distance_m
from arm_reconstruction.revolution import (
    arc_span_deg,
    fit_revolution,
    revolution_completion,
    revolution_mesh,
)

CAMERA_XY = np.array([0.6, 0.1])


def _seen_side(mesh: trimesh.Trimesh, count: int = 3000, noise_m: float = 0.0005, seed: int = 0):
    """Surface samples facing a camera at CAMERA_XY (and above), with their normals and noise."""
    rng = np.random.default_rng(seed)
    points, faces = trimesh.sample.sample_surface(mesh, count, seed=seed)
    normals = mesh.face_normals[faces]
    to_camera = np.column_stack([CAMERA_XY - points[:, :2], np.full(len(points), 0.4)])
    facing = np.einsum("ij,ij->i", normals, to_camera) > 0
    return points[facing] + rng.normal(0, noise_m, (facing.sum(), 3)), normals[facing]


def _vase() -> trimesh.Trimesh:
    heights = np.linspace(0.0, 0.16, 9)
    radii = 0.03 + 0.012 * np.sin(heights / 0.16 * np.pi)
    profile = np.concatenate([[[0, 0]], np.column_stack([radii, heights]), [[0, 0.16]]])
    mesh = trimesh.creation.revolve(profile, sections=64)
    mesh.apply_translation((0.05, -0.02, 0.0))
    return mesh


def test_an_upright_vase_seen_from_one_side_is_completed():
    vase = _vase()
    points, normals = _seen_side(vase)
    fit = fit_revolution(points, normals, 0.0)
    assert fit is not None
    assert np.allclose(fit.axis_xy, (0.05, -0.02), atol=0.002)
    solid = revolution_mesh(fit, 0.0)
    assert solid.is_watertight and solid.volume > 0
    assert chamfer_distance_m(solid, vase) < 0.002
    assert abs(solid.volume / vase.volume - 1.0) < 0.1


def test_boxes_flat_faces_and_lying_cylinders_are_not_revolutions():
    box = trimesh.creation.box((0.08, 0.05, 0.12))
    box.apply_translation((0.0, 0.0, 0.06))
    lying = trimesh.creation.cylinder(0.03, 0.14, sections=64)
    lying.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    lying.apply_translation((0.0, 0.0, 0.03))
    for shape in (box, lying):
        points, normals = _seen_side(shape)
        assert fit_revolution(points, normals, 0.0) is None
    face = trimesh.creation.box((0.002, 0.08, 0.1))
    face.apply_translation((0.0, 0.0, 0.05))
    points, normals = _seen_side(face)
    assert fit_revolution(points, normals, 0.0) is None


def test_a_cylinder_seen_only_at_its_top_is_not_guessed_below():
    cylinder = trimesh.creation.cylinder(0.03, 0.14, sections=64)
    cylinder.apply_translation((0.0, 0.0, 0.07))
    points, normals = _seen_side(cylinder)
    high = points[:, 2] > 0.09  # the lower part hidden behind another object
    assert fit_revolution(points[high], normals[high], 0.0) is None
    assert fit_revolution(points, normals, 0.0) is not None


def test_a_solid_that_fills_seen_empty_space_is_refused():
    vase = _vase()
    points, normals = _seen_side(vase)
    frame = GridFrame(np.array([-0.1, -0.17, 0.0]), 0.01, 32, 0.0)
    grid = np.zeros((4, 32, 32, 32), np.float32)
    assert revolution_completion(points, normals, frame, grid) is not None
    grid[2] = 1.0  # everything seen empty
    assert revolution_completion(points, normals, frame, grid) is None


def test_arc_span():
    assert np.isclose(arc_span_deg(np.radians([0.0, 90.0, 180.0])), 180.0)
    assert np.isclose(arc_span_deg(np.radians([350.0, 10.0])), 20.0)
    assert arc_span_deg(np.array([0.0])) == 0.0
