"""bench_recon's per-scene cache: OUT/cache/<run key>/scene_NNNNN.json (+ .npz of the qualitative
cases), written atomically, so an interrupted run resumes."""

from __future__ import annotations

import json
import pathlib

import numpy as np

from arm_benchmarks.methods import GROUND_TRUTH
from arm_benchmarks.recon.scoring import evaluate_scene
from arm_core.atomic_io import atomic_write, atomic_write_json


def cached_scene(index: int, cache_dir: pathlib.Path, config, pool_factory, reconstructors) -> dict:
    """Scene result from the cache, or evaluated now and cached (JSON + qualitative .npz)."""
    path = cache_dir / f"scene_{index:05d}.json"
    if path.is_file():
        return json.loads(path.read_text())
    result, qualitative = evaluate_scene(index, config, pool_factory(), reconstructors)
    if qualitative:
        atomic_write(cache_dir / f"scene_{index:05d}.npz", lambda tmp: _savez(tmp, qualitative))
    atomic_write_json(path, result)
    return result


def _savez(path: str, arrays: dict) -> None:
    with open(path, "wb") as handle:
        np.savez_compressed(handle, **arrays)


def load_cases(cache_dir: pathlib.Path, results: list[dict], count: int) -> list[dict]:
    """The `count` lowest-visibility cached qualitative cases, from distinct scenes."""
    candidates = []
    for result in results:
        path = cache_dir / f"scene_{result['scene']:05d}.npz"
        if not path.is_file():
            continue
        with np.load(path) as data:
            n = 0
            while f"{n}/object" in data.files:
                obj = int(data[f"{n}/object"])
                row = next(r for r in result["rows"] if r["object"] == obj)
                case = {k: data[f"{n}/{k}"] for k in ("rgb", "visible", "silhouette", "camera_eye")}
                for name in ("baseline", "arm", GROUND_TRUTH):
                    case[name] = (data[f"{n}/{name}/vertices"], data[f"{n}/{name}/faces"])
                    if name in row["methods"] and row["methods"][name]["chamfer_m"] is not None:
                        case[f"{name}_chamfer_m"] = row["methods"][name]["chamfer_m"]
                case |= {
                    "category": row["category"],
                    "visible_fraction": row["visible_fraction"],
                    "scene": result["scene"],
                }
                candidates.append(case)
                n += 1
    candidates.sort(key=lambda c: c["visible_fraction"])
    chosen, scenes = [], set()
    for case in candidates:
        if case["scene"] not in scenes:
            chosen.append(case)
            scenes.add(case["scene"])
        if len(chosen) == count:
            break
    return chosen
