import numpy as np
import pytest
import trimesh

from arm_benchmarks.pushability import main, tip_free_height


def _box(width_x: float, width_y: float, height: float) -> np.ndarray:
    box = trimesh.creation.box((width_x, width_y, height))
    return box.vertices + np.array([0.0, 0.0, height / 2])


def test_a_box_slides_below_its_half_width_over_the_friction():
    vertices = _box(0.04, 0.06, 0.10)
    com = np.array([0.0, 0.0, 0.05])
    assert tip_free_height(vertices, com, np.array([1.0, 0.0]), 0.5) == pytest.approx(0.02 / 0.5)
    assert tip_free_height(vertices, com, np.array([0.0, -2.0]), 0.9) == pytest.approx(0.03 / 0.9)
    diagonal = tip_free_height(vertices, com, np.array([1.0, 1.0]), 1.0)  # the x face is met first
    assert diagonal == pytest.approx(0.02 * np.sqrt(2))


def test_a_centre_of_mass_outside_the_base_or_a_point_base_cannot_be_pushed():
    vertices = _box(0.04, 0.04, 0.10)
    assert tip_free_height(vertices, np.array([0.05, 0.0, 0.05]), np.array([1.0, 0.0]), 0.5) == 0.0
    cone = trimesh.creation.cone(radius=0.03, height=0.08)
    upside_down = cone.vertices * np.array([1.0, 1.0, -1.0]) + np.array([0.0, 0.0, 0.08])
    assert tip_free_height(upside_down, np.array([0.0, 0.0, 0.06]), np.array([1.0, 0.0]), 0.5) == 0.0


def test_the_analysis_writes_its_summary_and_figure(tmp_path):
    assert main(["--samples", "4", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "summary.json").is_file() and (tmp_path / "hstar.png").is_file()
