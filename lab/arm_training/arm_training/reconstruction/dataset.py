"""Reading the bit-packed shards written by ``datagen``.

The whole split stays in memory bit-packed (about 3 KB per sample compressed on disk, 20 KB packed
in memory at d = 32) and batches are unpacked on demand, so no loader processes are needed.
"""

from __future__ import annotations

import json
import pathlib

import numpy as np
import torch

from arm_training.reconstruction.datagen import FORMAT, file_sha256

_PER_SAMPLE = ("visible_fraction", "visible_pixels", "category", "object_scale", "voxel_size_m", "table_height_m")


class DatasetError(RuntimeError):
    """Missing, corrupt or inconsistent dataset files."""


class VoxelDataset:
    """All samples of one split (``<root>/<split>/shard_*.npz``), optionally checked against the manifest.

    ``batch(indices)`` returns float32 tensors: ``grids [n, 4, d, d, d]`` (F1 own, F2 others,
    F3 observed empty, F4 unobserved), ``occupancy [n, d, d, d]`` (ground truth), ``others
    [n, d, d, d]`` (other objects' ground truth) and ``visible_fraction [n]``.
    """

    def __init__(self, root, split: str = "train", verify: bool = False, max_samples: int | None = None):
        folder = pathlib.Path(root) / split
        paths = sorted(folder.glob("shard_*.npz"))
        if not paths:
            raise DatasetError(f"no shards in {folder}; run `datagen --out {root} --split {split}` first")
        if verify:
            verify_manifest(folder)
        parts: dict[str, list] = {"grids_bits": [], "occupancy_bits": [], "others_bits": []}
        parts.update({key: [] for key in _PER_SAMPLE})
        resolution, k = None, None
        self.shards: list[tuple[str, int]] = []
        self.seeds: list[int] = []
        for path in paths:
            with np.load(path, allow_pickle=False) as shard:
                if str(shard["format"]) != FORMAT:
                    raise DatasetError(f"{path} is not a {FORMAT} shard")
                d = int(shard["resolution"])
                if resolution not in (None, d):
                    raise DatasetError(f"{path} has resolution {d}, other shards {resolution}")
                resolution = d
                shard_k = float(shard["k"])
                if k not in (None, shard_k):
                    raise DatasetError(f"{path} has grid k {shard_k}, other shards {k}")
                k = shard_k
                for key in parts:
                    parts[key].append(shard[key])
                self.shards.append((path.name, int(len(shard["visible_fraction"]))))
                self.seeds.append(int(shard["seed"]))
        self.resolution = int(resolution)
        self.k = float(k)  # grid side over the observed object diameter
        self.split = split
        arrays = {key: np.concatenate(value) for key, value in parts.items()}
        if max_samples is not None:
            arrays = {key: value[:max_samples] for key, value in arrays.items()}
        self._grids = arrays.pop("grids_bits")
        self._occupancy = arrays.pop("occupancy_bits")
        self._others = arrays.pop("others_bits")
        self.info = arrays

    def __len__(self) -> int:
        return len(self._grids)

    def batch(self, indices, device: str | torch.device = "cpu") -> dict[str, torch.Tensor]:
        """Samples `indices` as float32 tensors on `device`; the bits travel packed and are unpacked there
        (on a GPU the unpacking would otherwise bound the training speed)."""
        indices = np.asarray(indices, dtype=np.int64)
        d = self.resolution
        return {
            "grids": unpack_bits(self._grids[indices], (4, d, d, d), device),
            "occupancy": unpack_bits(self._occupancy[indices], (d, d, d), device),
            "others": unpack_bits(self._others[indices], (d, d, d), device),
            "visible_fraction": torch.from_numpy(self.info["visible_fraction"][indices]).to(device),
        }


def unpack_bits(bits: np.ndarray, shape: tuple[int, ...], device: str | torch.device = "cpu") -> torch.Tensor:
    """``[n, bytes]`` uint8 from ``np.packbits`` (big-endian bit order) -> float32 ``[n, *shape]`` on device."""
    packed = torch.from_numpy(np.ascontiguousarray(bits)).to(device)
    shifts = torch.arange(7, -1, -1, dtype=torch.uint8, device=packed.device)
    flat = ((packed[:, :, None] >> shifts) & 1).reshape(len(bits), -1)[:, : int(np.prod(shape))]
    return flat.reshape((len(bits), *shape)).to(torch.float32)


def verify_manifest(folder) -> dict:
    """Check every shard listed in ``manifest.json`` exists with its sha256; returns the manifest."""
    folder = pathlib.Path(folder)
    manifest_path = folder / "manifest.json"
    if not manifest_path.is_file():
        raise DatasetError(f"{manifest_path} is missing")
    manifest = json.loads(manifest_path.read_text())
    for shard in manifest["shards"]:
        path = folder / shard["file"]
        if not path.is_file() or file_sha256(path) != shard["sha256"]:
            raise DatasetError(f"shard {path} is missing or does not match its manifest checksum")
    return manifest


def random_symmetry(batch: dict[str, torch.Tensor], generator: torch.Generator) -> dict[str, torch.Tensor]:
    """One random symmetry of the square table-aligned grid for the whole batch: a rotation by a
    multiple of 90 degrees about +z and an optional mirror of x. Gravity and the table stay put."""
    quarter_turns = int(torch.randint(4, (1,), generator=generator))
    mirror = bool(torch.randint(2, (1,), generator=generator))

    def transform(tensor: torch.Tensor) -> torch.Tensor:
        x_dim = tensor.ndim - 3
        out = torch.rot90(tensor, quarter_turns, dims=(x_dim, x_dim + 1))
        return torch.flip(out, dims=(x_dim,)) if mirror else out

    return {key: transform(value) if value.ndim >= 4 else value for key, value in batch.items()}
