"""The benchmarks' caches are keyed by arm_benchmarks.run_key over the packages their results depend on."""

from arm_benchmarks import bench_manip, bench_seg
from arm_benchmarks.recon.config import RESULT_PACKAGES, BenchConfig
from arm_benchmarks.run_key import package_sources


def test_bench_seg_keys_frames_by_the_simulator_and_scores_by_the_segmentation_too():
    args = bench_seg.parse_args(["--seed", "0"])
    assert bench_seg.frames_key(args) == bench_seg.frames_key(bench_seg.parse_args(["--seed", "0"]))
    assert bench_seg.frames_key(args) != bench_seg.frames_key(bench_seg.parse_args(["--seed", "1"]))
    assert bench_seg.frames_key(args) != bench_seg.frames_key(bench_seg.parse_args(["--no-noise"]))
    assert bench_seg.scores_key(args) != bench_seg.frames_key(args)
    assert bench_seg.scores_key(args) == bench_seg.scores_key(bench_seg.parse_args(["--scenes", "7"]))


def test_bench_recon_key_covers_every_result_package_but_not_the_run_size():
    config = BenchConfig(seed=0)
    key = config.result_key(set())
    assert key == BenchConfig(seed=0, scenes=3, out="elsewhere", qualitative=0, threads=1).result_key(set())
    assert key != BenchConfig(seed=1).result_key(set())
    dependencies = {"arm_sim", "arm_segmentation", "arm_reconstruction", "arm_planner", "arm_benchmarks"}
    assert dependencies <= set(RESULT_PACKAGES)
    assert any(p.name == "views.py" for p in package_sources("arm_sim"))


def test_bench_manip_key_includes_the_methods_checkpoints():
    settings = {"steps": 200, "methods": ["ground-truth"]}
    assert bench_manip.result_key(settings) == bench_manip.result_key(dict(settings))
    assert bench_manip.result_key(settings) != bench_manip.result_key(settings | {"methods": ["ground-truth", "arm"]})
