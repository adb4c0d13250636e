from arm_benchmarks import bench_manip
from arm_reconstruction.pipeline import ReconstructionSettings


def test_paper_postprocessing_turns_off_the_test_time_stages_and_keeps_the_papers():
    settings = ReconstructionSettings(method="baseline", **bench_manip.PAPER_POSTPROCESSING)
    assert settings.stable_base_tilt_deg == 0.0
    assert not settings.join_parts
    assert not settings.snap_to_depth
    assert not settings.complete_revolutions
    assert not settings.complete_cuboids
    assert settings.remove_intersections
    assert ReconstructionSettings(method="baseline").join_parts  # the default pipeline keeps them
