"""Bags for robustness runs: a camera bag for load runs and broken bags a reader must refuse."""

from __future__ import annotations

import pathlib
import shutil

import numpy as np

from arm_bags.bags import write_bag
from arm_benchmarks.robustness.messages import camera_messages, joint_state_msg


def write_camera_bag(path, frames, rate_hz: float, storage: str = "mcap", joint_states: bool = True) -> dict:
    """A bag of the frames as a camera at rate_hz would publish them (stamps and receive times
    k / rate_hz), with joint states at the same instants. Returns messages per topic."""

    def messages():
        for k, frame in enumerate(frames):
            stamp_s = (k + 1) / rate_hz
            t_ns = int(round(stamp_s * 1e9))
            for topic, msg in camera_messages(frame, stamp_s).items():
                yield "/" + topic, t_ns, msg
            if joint_states:
                yield "/joint_states", t_ns, joint_state_msg(stamp_s)

    return write_bag(path, messages(), storage)


def broken_bags(folder, messages, fractions=(0.5, 0.9)) -> dict[str, pathlib.Path]:
    """Bags a reader must refuse with a BagError, by name: a good bag of `messages` (topic, stamp ns,
    message) in each storage truncated to each fraction of its bytes, an empty directory, a missing
    path, random bytes named .mcap and a text file."""
    folder = pathlib.Path(folder)
    messages = list(messages)
    bags = {}
    for storage in ("mcap", "sqlite3"):
        good = folder / f"good_{storage}"
        write_bag(good, messages, storage)
        for fraction in fractions:
            path = folder / f"truncated_{storage}_{int(fraction * 100)}"
            shutil.copytree(good, path)
            storage_file = next(f for f in path.iterdir() if f.suffix in (".mcap", ".db3"))
            data = storage_file.read_bytes()
            storage_file.write_bytes(data[: int(len(data) * fraction)])
            bags[f"{storage} truncated to {int(fraction * 100)} %"] = path
    (folder / "empty_dir").mkdir()
    bags["empty directory"] = folder / "empty_dir"
    bags["missing path"] = folder / "does_not_exist"
    garbage = folder / "garbage.mcap"
    garbage.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    bags["random bytes .mcap"] = garbage
    (folder / "notes.txt").write_text("not a bag")
    bags["text file"] = folder / "notes.txt"
    return bags
