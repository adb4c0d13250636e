"""Training-data shards of the segmentation's learned parts: one seeded scene per .npz file, made
in parallel processes with a progress bar; shards that exist are kept, so a run resumes."""

from __future__ import annotations

import pathlib
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed

from tqdm import tqdm


def shard_path(root, split: str, seed: int) -> pathlib.Path:
    """<root>/<split>/shard_<seed>.npz"""
    return pathlib.Path(root) / split / f"shard_{seed:06d}.npz"


def run_jobs(job: Callable[[dict], int], jobs: list[dict], workers: int, desc: str) -> int:
    """Run job(spec) for every spec in jobs (in `workers` processes when > 1; job must then be a
    module-level function), with a progress bar; returns the sum of what the jobs return."""
    total = 0
    with tqdm(total=len(jobs), desc=desc, unit="shard") as bar:
        if workers <= 1:
            for spec in jobs:
                total += job(spec)
                bar.update(1)
        else:
            with ProcessPoolExecutor(max_workers=workers) as executor:
                for future in as_completed([executor.submit(job, spec) for spec in jobs]):
                    total += future.result()
                    bar.update(1)
    return total
