import numpy as np
import pytest
import trimesh

from arm_sim.objects import CATEGORY_BUILDERS, HELDOUT_CATEGORIES, TRAIN_CATEGORIES, make_object, object_pool


@pytest.mark.parametrize("category", sorted(CATEGORY_BUILDERS))
def test_procedural_objects_are_watertight_metric_and_rest_on_their_base(category):
    model = make_object(category, np.random.default_rng(3))
    assert model.mesh.is_watertight and model.mesh.volume > 0
    assert np.isclose(np.max(model.mesh.extents), 0.08, atol=1e-6)
    assert abs(model.mesh.bounds[0][2]) < 1e-9  # bottom on z = 0
    assert np.allclose(model.mesh.bounds.mean(0)[:2], 0.0, atol=1e-9)
    union_of_parts = (
        trimesh.boolean.union(model.convex_parts, engine="manifold")
        if len(model.convex_parts) > 1
        else model.convex_parts[0]
    )
    assert np.isclose(union_of_parts.volume, model.mesh.volume, rtol=1e-3)


def test_train_and_heldout_categories_are_disjoint():
    assert not set(TRAIN_CATEGORIES) & set(HELDOUT_CATEGORIES)
    assert len(TRAIN_CATEGORIES) >= 5 and len(HELDOUT_CATEGORIES) >= 4


def test_external_mesh_folder_is_a_pool(tmp_path):
    trimesh.creation.box(extents=(0.05, 0.04, 0.1)).export(tmp_path / "block.stl")
    trimesh.creation.icosphere(radius=0.03).export(tmp_path / "ball.obj")
    (tmp_path / "notes.txt").write_text("not a mesh")
    pool = object_pool(str(tmp_path))
    assert len(pool) == 2
    model = pool.sample(np.random.default_rng(0))
    assert model.category == "external" and model.mesh.is_watertight and model.convex_parts
    assert abs(model.mesh.bounds[0][2]) < 1e-9


def test_bad_pool_requests_fail_clearly(tmp_path):
    with pytest.raises(ValueError, match="no .obj"):
        object_pool(str(tmp_path))
    with pytest.raises(ValueError, match="split"):
        object_pool(None, split="validation")
    with pytest.raises(ValueError, match="unknown category"):
        make_object("spaceship", np.random.default_rng(0))
