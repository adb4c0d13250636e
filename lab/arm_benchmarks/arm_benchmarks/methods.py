"""Method names shared by the benchmarks: one name for the ground truth, the reconstruction methods'
canonical names otherwise."""

from arm_reconstruction.network import canonical_method

GROUND_TRUTH = "ground-truth"
GROUND_TRUTH_ALIASES = {"ground-truth", "ground_truth", "groundtruth", "ground truth", "gt"}


def benchmark_method(name: str) -> str:
    """Canonical benchmark method name ('ground_truth', as in older result files, -> GROUND_TRUTH);
    raises ValueError for an unknown name."""
    if str(name).strip().lower() in GROUND_TRUTH_ALIASES:
        return GROUND_TRUTH
    return canonical_method(name)
