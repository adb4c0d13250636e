import json

import numpy as np
import pytest
import torch
import trimesh

from arm_benchmarks.bench_recon import parse_args, run
from arm_benchmarks.recon.config import BenchConfig
from arm_benchmarks.recon.matching import match_instances
from arm_benchmarks.recon.physics import scene_stability
from arm_benchmarks.recon.plots import plot_by_visibility, plot_qualitative, plot_stability
from arm_benchmarks.recon.report import write_report
from arm_benchmarks.recon.scoring import load_reconstructors
from arm_benchmarks.recon.summary import priors_earn_their_place, summarise, visibility_bin
from arm_planner.twin import TwinObject
from arm_training.reconstruction.box_dataset import tiny_train_config, write_box_dataset
from arm_training.reconstruction.train import train

torch.set_num_threads(2)


def box_object(object_id, extents, T_world_object):
    mesh = trimesh.creation.box(extents=extents)
    return TwinObject(object_id, np.asarray(T_world_object, dtype=np.float64), mesh, [mesh.copy()])


def pose(xyz, rotation=None):
    T = np.eye(4)
    T[:3, :3] = np.eye(3) if rotation is None else rotation
    T[:3, 3] = xyz
    return T


def test_stability_separates_resting_falling_and_toppling_objects():
    tilt = trimesh.transformations.rotation_matrix(np.radians(30), (1, 0, 0))[:3, :3]
    objects = [
        box_object(1, (0.06, 0.06, 0.04), pose((0.0, 0.0, 0.02))),
        box_object(2, (0.06, 0.06, 0.04), pose((0.3, 0.0, 0.07))),
        box_object(3, (0.02, 0.02, 0.2), pose((-0.3, 0.0, 0.1 * np.cos(np.radians(30)) + 0.012), tilt)),
        box_object(4, (0.0, 0.0, 0.0), pose((0.0, 0.3, 0.1))),
    ]
    moved = scene_stability(objects, 0.0, (0.7, 0.5), duration_s=2.0, timestep_s=0.01)
    assert set(moved) == {1, 2, 3}, "a degenerate object is skipped as by the planner's twin"
    assert moved[1] < 0.002
    assert moved[2] == pytest.approx(0.05, abs=0.006)
    assert moved[3] > 0.03


def test_instances_are_matched_one_to_one_above_half_overlap():
    truth = np.zeros((20, 20), np.uint16)
    truth[2:8, 2:8], truth[10:18, 10:18], truth[2:5, 12:15] = 1, 2, 3
    predicted = np.zeros_like(truth)
    predicted[2:8, 2:7] = 4  # IoU 5/6 with object 1
    predicted[10:18, 10:18] = 7
    predicted[10:18, 14:18] = 8  # splits object 2: IoU 0.5 each, not a match
    predicted[2:5, 12:14] = 9
    assert match_instances(predicted, truth, [1, 2, 3]) == {1: 4, 3: 9}
    assert match_instances(truth, truth, [1, 2, 3]) == {1: 1, 2: 2, 3: 3}


def test_visibility_bins():
    assert [visibility_bin(v) for v in (0.0, 0.19, 0.2, 0.59, 0.8, 1.0)] == [
        "0.0-0.2",
        "0.0-0.2",
        "0.2-0.4",
        "0.4-0.6",
        "0.8-1.0",
        "0.8-1.0",
    ]


def test_arguments_are_validated():
    config = parse_args(["--scenes", "3", "--methods", "arm,visible-only", "--segmentation", "predicted"])
    assert config.scenes == 3 and config.methods == ("visible-only", "arm") and config.segmentation == "predicted"
    with pytest.raises(SystemExit):
        parse_args(["--methods", "genre"])
    with pytest.raises(SystemExit):
        parse_args(["--scenes", "0"])


@pytest.fixture(scope="module")
def baseline_only_checkpoints(tmp_path_factory):
    """A baseline checkpoint from two steps of the project trainer; no ARM checkpoints."""

    root = tmp_path_factory.mktemp("recon_data")
    write_box_dataset(root, "train", shards=1, per_shard=8, seed=0)
    write_box_dataset(root, "test", shards=1, per_shard=4, seed=1)
    folder = tmp_path_factory.mktemp("checkpoints")
    train(tiny_train_config(root, folder / "baseline.pt", "baseline", steps=2), progress=False)
    return folder


def small_config(out, checkpoints, **changes):
    fields = dict(
        scenes=1,
        seed=3,
        min_objects=3,
        max_objects=4,
        view="random",
        out=str(out),
        methods=("visible-only", "baseline", "arm", "ground-truth"),
        checkpoint_dir=str(checkpoints),
        chamfer_samples=512,
        iou_resolution=32,
        qualitative=1,
    )
    return BenchConfig(**(fields | changes))


@pytest.mark.slow
def test_end_to_end_run_reports_measured_methods_and_skips_missing_ones(tmp_path, baseline_only_checkpoints):
    config = small_config(tmp_path, baseline_only_checkpoints)
    summary = run(config, progress=False)
    methods = summary["methods"]
    assert list(methods) == list(config.methods)
    assert methods["arm"]["status"] == "skipped" and "no checkpoint" in methods["arm"]["reason"]
    n = summary["objects"]
    assert n >= 1 and sum(summary["objects_by_visibility"].values()) == n
    visible = methods["visible-only"]
    assert visible["status"] == "ok" and visible["n"] == n and visible["n_empty"] == 0
    assert 0.0 < visible["chamfer_m"] < 0.1 and 0.0 < visible["iou"] < 1.0
    assert sum(b["n"] for b in visible["by_visibility"].values()) == n
    baseline = methods["baseline"]
    assert baseline["status"] == "ok" and baseline["n_chamfer"] + baseline["n_empty"] == n
    truth = methods["ground-truth"]
    assert truth["chamfer_m"] is None and truth["iou"] is None and truth["stable_fraction"] >= 0.5
    cached = json.loads(next((tmp_path / "cache").rglob("scene_00000.json")).read_text())
    moved = [r["methods"]["ground-truth"]["displacement_m"] for r in cached["rows"]]
    assert truth["displacement_m_mean"] == pytest.approx(np.mean([m for m in moved if np.isfinite(m)]))
    report = (tmp_path / "report.md").read_text()
    assert "**arm: skipped**" in report and "CD = 0.5 * (mean" in report
    for name in ("summary.json", "chamfer_by_visibility.png", "stability.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert json.loads((tmp_path / "summary.json").read_text())["objects"] == n

    again = run(config, progress=False)
    assert again["run"]["scenes_computed"] == 0 and summary["run"]["scenes_computed"] == 1
    assert again["methods"] == summary["methods"]


@pytest.mark.slow
def test_predicted_segmentation_is_matched_to_the_true_objects(tmp_path, baseline_only_checkpoints):
    config = small_config(
        tmp_path,
        baseline_only_checkpoints,
        segmentation="predicted",
        methods=("visible-only", "ground-truth"),
        qualitative=0,
    )
    summary = run(config, progress=False)
    visible = summary["methods"]["visible-only"]
    assert 0 <= summary["objects_matched"] <= summary["objects"]
    assert visible["n_empty"] == summary["objects"] - summary["objects_matched"]
    assert "predicted by arm_segmentation.segment" in (tmp_path / "report.md").read_text()


def test_visible_only_needs_no_checkpoint(tmp_path):
    reconstructors, skipped, checkpoints = load_reconstructors(("visible-only",), str(tmp_path))
    assert list(reconstructors) == ["visible-only"] and not skipped and not checkpoints


def test_the_run_pipeline_settings_reach_every_method(tmp_path):
    config = BenchConfig(smoothing_iterations=3, join_parts=False, stable_base_tilt_deg=0.0)
    reconstructors, _, _ = load_reconstructors(("visible-only",), str(tmp_path), config.pipeline())
    settings = reconstructors["visible-only"].settings
    assert (settings.smoothing_iterations, settings.join_parts, settings.stable_base_tilt_deg) == (3, False, 0.0)


def synthetic_results():
    """Two objects: arm halves baseline's Chamfer; one arm object and the baseline ones move."""

    def entry(chamfer, moved):
        return {
            "empty": chamfer is None,
            "chamfer_m": chamfer,
            "iou": 0.0 if chamfer is None else 0.5,
            "displacement_m": moved,
        }

    rows = [
        {
            "scene": 0,
            "object": 0,
            "category": "vase",
            "visible_fraction": 0.1,
            "matched": True,
            "methods": {
                "baseline": entry(0.02, 0.05),
                "arm": entry(0.01, 0.001),
                "ground-truth": {**entry(None, 0.0), "empty": False, "iou": None},
            },
        },
        {
            "scene": 0,
            "object": 1,
            "category": "lamp",
            "visible_fraction": 0.9,
            "matched": True,
            "methods": {
                "baseline": entry(0.004, 0.02),
                "arm": entry(0.002, 0.03),
                "ground-truth": {**entry(None, 0.002), "empty": False, "iou": None},
            },
        },
    ]
    timing = {m: {"total_s": 1.0} for m in ("baseline", "arm", "ground-truth")}
    return [{"scene": 0, "rows": rows, "timing_s": timing, "wall_s": 3.0, "cpu_s": 2.0}]


def test_summary_and_targets_follow_the_measurements():
    config = BenchConfig(methods=("baseline", "arm", "arm-c", "ground-truth"))
    summary = summarise(synthetic_results(), config, {"arm-c": "no checkpoint"}, {})
    methods = summary["methods"]
    assert methods["arm-c"] == {"status": "skipped", "reason": "no checkpoint"}
    assert methods["arm"]["chamfer_m"] == pytest.approx(0.006)
    assert methods["baseline"]["chamfer_m"] == pytest.approx(0.012)
    assert methods["arm"]["stable_fraction"] == 0.5 and methods["ground-truth"]["stable_fraction"] == 1.0
    low_bin = methods["arm"]["by_visibility"]["0.0-0.2"]
    assert low_bin["n"] == 1 and low_bin["chamfer_m"] == pytest.approx(0.01) and low_bin["stable_fraction"] == 1.0
    assert methods["arm"]["by_visibility"]["0.4-0.6"]["n"] == 0
    targets = summary["targets"]
    assert targets["arm_chamfer_reduction_vs_baseline"]["value"] == pytest.approx(0.5)
    assert targets["arm_chamfer_reduction_vs_baseline"]["met"]
    assert targets["arm_lower_chamfer_every_bin"]["value"] == {
        "0.0-0.2": True,
        "0.2-0.4": None,
        "0.4-0.6": None,
        "0.6-0.8": None,
        "0.8-1.0": True,
    }
    assert not targets["arm_lower_chamfer_every_bin"]["met"], "bins without objects are not met"
    assert targets["arm_chamfer_m"]["value"] == pytest.approx(0.006) and not targets["arm_chamfer_m"]["met"]
    assert targets["arm_chamfer_m_visible_0.8_1.0"]["value"] == pytest.approx(0.002)
    assert targets["arm_chamfer_m_visible_0.8_1.0"]["met"]
    assert targets["priors_earn_their_place"] == {"value": None, "met": None}, "no arm-c-s in this run"
    assert not targets["arm_stable_fraction"]["met"]
    assert targets["arm_stable_gap_to_ground_truth"]["value"] == pytest.approx(0.5)
    truth, arm = methods["ground-truth"], methods["arm"]
    assert truth["displacement_m_mean"] == pytest.approx(0.001)
    assert truth["displacement_m_median"] == pytest.approx(0.001)
    assert arm["displacement_m_mean"] == pytest.approx(0.0155) and arm["stable_ci90"][0] < 0.5 < arm["stable_ci90"][1]
    assert methods["baseline"]["stable_fraction"] == 0.0 and methods["baseline"]["stable_ci90"][0] == 0.0


def test_plots_and_report_are_written(tmp_path):
    config = BenchConfig(methods=("baseline", "arm", "ground-truth"))
    summary = summarise(synthetic_results(), config, {}, {})
    plot_by_visibility(summary, tmp_path / "a.png")
    plot_stability(summary, tmp_path / "b.png")
    box = trimesh.creation.box(extents=(0.05, 0.05, 0.1))
    case = {
        "rgb": np.zeros((40, 40, 3), np.uint8),
        "visible": np.eye(40, dtype=bool),
        "silhouette": np.ones((40, 40), bool),
        "camera_eye": np.array([1.0, 0.0, 0.5]),
        "category": "vase",
        "visible_fraction": 0.1,
        "arm_chamfer_m": 0.004,
    }
    for name in ("baseline", "arm", "ground-truth"):
        case[name] = (box.vertices, box.faces)
    plot_qualitative([case], tmp_path / "c.png")
    write_report(summary, tmp_path / "report.md", ["a.png"])
    assert all((tmp_path / f).stat().st_size > 1000 for f in ("a.png", "b.png", "c.png"))
    report = (tmp_path / "report.md").read_text()
    assert "| arm | 2 | 0 | 6.00" in report and "| 0.0-0.2 | 1 | 20.00 | 10.00 | 50.0% |" in report


def test_priors_earn_their_place_needs_disjoint_intervals():
    arm = {
        "status": "ok",
        "chamfer_m": 0.006,
        "chamfer_m_ci90": [0.0055, 0.0065],
        "stable_fraction": 0.9,
        "stable_ci90": [0.85, 0.94],
    }
    close = {
        "status": "ok",
        "chamfer_m": 0.0066,
        "chamfer_m_ci90": [0.006, 0.0072],
        "stable_fraction": 0.88,
        "stable_ci90": [0.83, 0.92],
    }
    far = {**close, "chamfer_m": 0.008, "chamfer_m_ci90": [0.0075, 0.0085]}
    assert not priors_earn_their_place(arm, close)["met"]
    assert priors_earn_their_place(arm, far)["met"]
    assert not priors_earn_their_place({**arm, "stable_fraction": 0.8}, far)["met"], "worse on stability"
