"""Training of the reconstruction network and its ablations (paper Sec. 4, appendix C).

Variants: ``baseline`` (F1 only, reconstruction loss), ``arm-c-s`` (four channels, reconstruction
loss), ``arm-c`` (+ stability prior), ``arm`` (+ stability and connectivity priors). Adam, lr 2e-4,
batch 16 as in the paper. CPU by default, CUDA when present (``--device auto``), and data-parallel
across GPUs or machines when launched with ``torchrun`` (the batch is split over the processes).

Progress is saved every ``--checkpoint-every`` steps to ``<work-dir>/state.pt`` (model, optimiser,
random state, history, config), so an interrupted run continues where it stopped. At the end the
model is evaluated on the held-out split and written with ``save_checkpoint`` (config, metrics,
history, command and timing inside), and the training curves go to ``<work-dir>/curves.png``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pathlib
import shlex
import signal
import sys
import tempfile
import time

import numpy as np
import torch
from scipy import ndimage
from tqdm import tqdm

from arm_core.atomic_io import atomic_write
from arm_reconstruction.checkpoint import save_checkpoint
from arm_reconstruction.dataset import VoxelDataset, random_symmetry
from arm_reconstruction.losses import (
    connectivity_loss,
    reconstruction_loss,
    stability_loss,
    stability_value_and_gradient,
)
from arm_reconstruction.network import VARIANTS, build_model, select_input_channels

PRIORS = {"baseline": (), "arm-c-s": (), "arm-c": ("stability",), "arm": ("stability", "connectivity")}


@dataclasses.dataclass
class TrainConfig:
    variant: str = "arm"
    data: str = "data/arm_dataset"
    train_split: str = "train"
    test_split: str = "test"
    out: str = ""
    work_dir: str = ""
    steps: int = 5000
    batch_size: int = 16
    lr: float = 2e-4
    pos_weight: float = 1.0
    surface_weight: float = 1.0
    stability_weight: float = 1e-5  # per voxel ~32768x this against the mean cross-entropy (model cards)
    connectivity_weight: float = 1e-4  # 1e-2 diverged here: its detour term inflated the shapes
    connectivity_factor: int = 2
    connectivity_endpoints: int = 16
    base_channels: int = 16  # on the shared 2-core CPU 16 trained ~2.3x faster per step than 32
    augment: bool = True
    device: str = "auto"
    threads: int = 2
    seed: int = 0
    checkpoint_every: int = 200
    eval_every: int = 1000
    eval_samples: int = 512
    final_eval_samples: int = 0
    time_limit_min: float = 0.0
    save_float16: bool = True
    init_from: str = ""

    def __post_init__(self):
        if self.variant not in PRIORS:
            raise ValueError(f"unknown variant {self.variant!r}; choose one of {sorted(PRIORS)}")
        self.out = self.out or f"results/train/{self.variant}/{self.variant}.pt"
        self.work_dir = self.work_dir or str(pathlib.Path(self.out).parent)


def _distributed() -> tuple[int, int, int]:
    """(rank, world size, local rank) when launched by torchrun, else (0, 1, 0)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1, 0
    return int(os.environ["RANK"]), world, int(os.environ.get("LOCAL_RANK", "0"))


def _device(name: str, local_rank: int) -> torch.device:
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    device = torch.device(name)
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise SystemExit("--device cuda requested but CUDA is not available")
        device = torch.device("cuda", local_rank if device.index is None else device.index)
        torch.cuda.set_device(device)
    return device


def losses_for_batch(logits, batch, config: TrainConfig) -> dict[str, torch.Tensor]:
    """The variant's loss terms (unweighted) and their weighted sum under ``total``."""
    terms = {
        "reconstruction": reconstruction_loss(logits, batch["occupancy"], config.pos_weight, config.surface_weight)
    }
    total = terms["reconstruction"]
    unobserved = batch["grids"][:, 3] > 0.5
    if "stability" in PRIORS[config.variant]:
        terms["stability"] = stability_loss(logits, batch["others"], unobserved)
        total = total + config.stability_weight * terms["stability"]
    if "connectivity" in PRIORS[config.variant]:
        terms["connectivity"] = connectivity_loss(
            logits, unobserved, config.connectivity_factor, config.connectivity_endpoints
        )
        total = total + config.connectivity_weight * terms["connectivity"]
    terms["total"] = total
    return terms


def voxel_metrics(
    probabilities: np.ndarray, occupancy: np.ndarray, voxel_size_m: np.ndarray, others: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """Per-sample IoU at 0.5, symmetric voxel Chamfer distance (metres: mean distance from each
    predicted voxel centre to the nearest true one plus the converse), whether the thresholded
    prediction is statically stable (stability prior P(E) > 0.5 on 0/1 occupancy, table and the
    other objects' true occupancy as support) and whether it is one 26-connected component."""
    predicted = probabilities >= 0.5
    truth = occupancy >= 0.5
    intersection = (predicted & truth).sum(axis=(1, 2, 3))
    union = (predicted | truth).sum(axis=(1, 2, 3))
    iou = np.where(union > 0, intersection / np.maximum(union, 1), 1.0)
    chamfer = np.zeros(len(predicted))
    components = np.zeros(len(predicted), dtype=np.int64)
    structure = np.ones((3, 3, 3), bool)
    for n in range(len(predicted)):
        if predicted[n].any() and truth[n].any():
            to_truth = ndimage.distance_transform_edt(~truth[n])[predicted[n]].mean()
            to_predicted = ndimage.distance_transform_edt(~predicted[n])[truth[n]].mean()
            chamfer[n] = (to_truth + to_predicted) * voxel_size_m[n]
        else:
            chamfer[n] = np.nan
        components[n] = ndimage.label(predicted[n], structure)[1]
    result = {"iou": iou, "chamfer_m": chamfer, "single_component": components == 1}
    if others is not None:
        hard_logits = torch.from_numpy(np.where(predicted, 30.0, -30.0).astype(np.float32))
        log_stable, _ = stability_value_and_gradient(hard_logits, torch.from_numpy(others), with_gradient=False)
        result["stable"] = (log_stable.numpy() > np.log(0.5)) & predicted.any(axis=(1, 2, 3))
    return result


def evaluate(model, dataset: VoxelDataset, device, max_samples: int = 512, batch_size: int = 32) -> dict:
    """Mean held-out metrics over the first ``max_samples`` samples (all, by visibility bins)."""
    model.eval()
    count = min(len(dataset), max_samples) if max_samples else len(dataset)
    parts: dict[str, list] = {}
    with torch.no_grad():
        for start in range(0, count, batch_size):
            index = np.arange(start, min(start + batch_size, count))
            batch = dataset.batch(index, device)
            logits = model(select_input_channels(batch["grids"], model.in_channels))
            metrics = voxel_metrics(
                torch.sigmoid(logits).float().cpu().numpy(),
                batch["occupancy"].cpu().numpy(),
                dataset.info["voxel_size_m"][index],
                batch["others"].cpu().numpy(),
            )
            metrics["visible_fraction"] = dataset.info["visible_fraction"][index]
            for key, value in metrics.items():
                parts.setdefault(key, []).append(value)
    model.train()
    values = {key: np.concatenate(value) for key, value in parts.items()}
    occluded = values.pop("visible_fraction") < 0.7
    summary = {"samples": int(count), "occluded_samples": int(occluded.sum())}
    for key, value in values.items():
        summary[key] = _finite_mean(value)
        summary[f"{key}_occluded"] = _finite_mean(value[occluded])
    return summary


def _finite_mean(values: np.ndarray) -> float | None:
    """Mean over the defined entries (Chamfer is undefined for an empty prediction), None if none."""
    values = np.asarray(values, dtype=np.float64)
    defined = values[np.isfinite(values)]
    return float(defined.mean()) if len(defined) else None


def plot_curves(history: list[dict], evaluations: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(11, 4))
    steps = np.array([h["step"] for h in history])
    for key in ("total", "reconstruction", "stability", "connectivity"):
        values = np.array([h.get(key, np.nan) for h in history], dtype=float)
        if len(values) and np.isfinite(values).any():
            window = max(1, len(values) // 50)
            smooth = np.convolve(values, np.ones(window) / window, mode="valid")
            axes[0].plot(steps[window - 1 :], smooth, label=key)
    axes[0].set_yscale("symlog", linthresh=1e-3)
    axes[0].set_xlabel("step")
    axes[0].set_title("training losses (unweighted terms, moving average)")
    axes[0].legend()
    if evaluations:
        eval_steps = [e["step"] for e in evaluations]
        for key in ("iou", "iou_occluded", "stable", "single_component"):
            if key in evaluations[0]:
                axes[1].plot(eval_steps, [e[key] for e in evaluations], marker="o", label=key)
        axes[1].set_xlabel("step")
        axes[1].set_title("held-out metrics")
        axes[1].legend()
    figure.tight_layout()
    pathlib.Path(path).parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _save_state(path: pathlib.Path, state: dict) -> None:
    atomic_write(path, lambda tmp: torch.save(state, tmp))


class _StopFlag:
    """Set by SIGTERM so the loop can save its state and exit cleanly."""

    def __init__(self):
        self.stop = False
        self._previous = signal.signal(signal.SIGTERM, self._handler)

    def _handler(self, signum, frame):
        self.stop = True

    def restore(self) -> None:
        signal.signal(signal.SIGTERM, self._previous)


def train(config: TrainConfig, command: str = "", progress: bool = True) -> dict:
    """Run (or resume) a training; returns the final held-out metrics and timing."""
    rank, world, local_rank = _distributed()
    if world > 1:
        backend = "nccl" if config.device != "cpu" and torch.cuda.is_available() else "gloo"
        torch.distributed.init_process_group(backend)
    device = _device(config.device, local_rank)
    if device.type == "cpu":
        torch.set_num_threads(max(1, config.threads))
    if config.batch_size % world:
        raise SystemExit(f"--batch-size {config.batch_size} must be divisible by the {world} processes")
    per_process_batch = config.batch_size // world
    work_dir = pathlib.Path(config.work_dir)
    state_path = work_dir / "state.pt"

    train_set = VoxelDataset(config.data, config.train_split)
    test_set = VoxelDataset(config.data, config.test_split) if rank == 0 else None
    torch.manual_seed(config.seed)
    model = build_model(config.variant, train_set.resolution, config.base_channels).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    rng = np.random.default_rng([config.seed, rank])
    augment_generator = torch.Generator().manual_seed(config.seed * 1000 + rank)
    step, history, evaluations, elapsed_s = 0, [], [], 0.0
    start_path = state_path if state_path.is_file() else pathlib.Path(config.init_from) if config.init_from else None
    if start_path is not None:
        state = torch.load(start_path, map_location=device, weights_only=False)
        state_variant = state["config"]["variant"]
        if start_path == state_path and state_variant != config.variant:
            raise SystemExit(f"{state_path} belongs to variant {state_variant}, not {config.variant}")
        if VARIANTS[state_variant] != VARIANTS[config.variant]:
            raise SystemExit(f"--init-from {start_path}: variant {state_variant} reads other input channels")
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        step, history, evaluations = state["step"], state["history"], state["evaluations"]
        elapsed_s = state["elapsed_s"]
        if rank < len(state["numpy_rng"]):
            rng.bit_generator.state = state["numpy_rng"][rank]
        augment_generator.set_state(state["augment_rng"])
    train_model = model
    if world > 1:
        ids = [device.index] if device.type == "cuda" else None
        train_model = torch.nn.parallel.DistributedDataParallel(model, device_ids=ids)

    def save_state() -> None:
        if rank == 0:
            _save_state(
                state_path,
                {
                    "config": dataclasses.asdict(config),
                    "model": model.state_dict(),
                    "optimizer": optimizer.state_dict(),
                    "step": step,
                    "history": history,
                    "evaluations": evaluations,
                    "elapsed_s": elapsed_s,
                    "numpy_rng": [rng.bit_generator.state],
                    "augment_rng": augment_generator.get_state(),
                },
            )

    stop = _StopFlag()
    memory_format = torch.channels_last_3d if device.type == "cpu" else torch.contiguous_format
    model.train()
    bar = tqdm(total=config.steps, initial=step, desc=f"train {config.variant}", disable=not progress or rank)
    session_start = time.perf_counter()
    try:
        while step < config.steps and not stop.stop:
            session_s = time.perf_counter() - session_start
            out_of_time = bool(config.time_limit_min) and session_s > 60 * config.time_limit_min
            if world > 1:
                flag = torch.tensor([float(out_of_time)], device=device)
                torch.distributed.all_reduce(flag, op=torch.distributed.ReduceOp.MAX)
                out_of_time = bool(flag.item())
            if out_of_time:
                break
            tick = time.perf_counter()
            batch = train_set.batch(rng.choice(len(train_set), per_process_batch, replace=False))
            if config.augment:
                batch = random_symmetry(batch, augment_generator)
            batch = {key: value.to(device, non_blocking=True) for key, value in batch.items()}
            inputs = select_input_channels(batch["grids"], VARIANTS[config.variant])
            logits = train_model(inputs.contiguous(memory_format=memory_format))
            terms = losses_for_batch(logits, batch, config)
            optimizer.zero_grad(set_to_none=True)
            terms["total"].backward()
            optimizer.step()
            step += 1
            elapsed_s += time.perf_counter() - tick
            history.append({"step": step, **{key: float(value.detach()) for key, value in terms.items()}})
            bar.update(1)
            bar.set_postfix(loss=f"{history[-1]['total']:.4f}")
            if rank == 0 and config.eval_every and step % config.eval_every == 0 and step < config.steps:
                evaluations.append({"step": step, **evaluate(model, test_set, device, config.eval_samples)})
            if step % config.checkpoint_every == 0:
                save_state()
    except KeyboardInterrupt:
        stop.stop = True
    finally:
        bar.close()
        stop.restore()
        save_state()
    if stop.stop or step < config.steps and not config.time_limit_min:
        return {"interrupted": True, "step": step}
    if rank != 0:
        torch.distributed.destroy_process_group()
        return {"step": step}
    metrics = evaluate(model, test_set, device, max_samples=config.final_eval_samples)
    evaluations.append({"step": step, **metrics})
    plot_curves(history, evaluations, work_dir / "curves.png")
    result = {
        "variant": config.variant,
        "steps": step,
        "samples_seen": step * config.batch_size,
        "train_wall_s": elapsed_s,
        "device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
        "processes": world,
        "train_samples": len(train_set),
        "train_shards": len(train_set.shards),
        "train_seeds": [min(train_set.seeds), max(train_set.seeds)],
        "test_seeds": [min(test_set.seeds), max(test_set.seeds)],
        "test_samples": len(test_set),
        "test_shards": len(test_set.shards),
        "heldout_metrics": metrics,
        "command": command,
    }
    if config.save_float16:
        model.half()  # half the file size; load_checkpoint copies the weights into a float32 model
    save_checkpoint(
        config.out,
        model,
        config={"training": dataclasses.asdict(config)},
        extra={
            **result,
            "weights_dtype": "float16" if config.save_float16 else "float32",
            "evaluations": evaluations,
            "loss_history": _thin(history, 400),
        },
    )
    model.float()
    (work_dir / "result.json").write_text(json.dumps(result, indent=1))
    if world > 1:
        torch.distributed.destroy_process_group()
    return result


def _thin(history: list[dict], points: int) -> list[dict]:
    stride = max(1, len(history) // points)
    return history[::stride]


def measure_training(data_dir: str | None = None, steps: int = 8, seed: int = 0, threads: int = 2) -> dict:
    """Figures for results/perf: ``datagen_samples_per_s`` (one training shard made from scratch,
    one process) and ``train_samples_per_s`` (``arm`` variant with both priors, the default network
    size, batch 16, CPU with ``threads`` threads)."""
    from arm_reconstruction import datagen

    with tempfile.TemporaryDirectory() as scratch:
        root = pathlib.Path(data_dir or scratch)
        start = time.perf_counter()
        arrays = datagen.generate_shard(seed=10_000_000 + seed, split="train")
        datagen_s = time.perf_counter() - start
        samples_made = len(arrays["visible_fraction"])
        datagen.write_shard(datagen.shard_path(root, "train", 0), arrays)
        dataset = VoxelDataset(root, "train")
        torch.set_num_threads(threads)
        config = TrainConfig(variant="arm", data=str(root), device="cpu")
        model = build_model("arm", dataset.resolution, config.base_channels)
        optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
        rng = np.random.default_rng(seed)

        def one_step():
            batch = dataset.batch(rng.choice(len(dataset), config.batch_size, replace=len(dataset) < 16))
            logits = model(batch["grids"].contiguous(memory_format=torch.channels_last_3d))
            terms = losses_for_batch(logits, batch, config)
            optimizer.zero_grad(set_to_none=True)
            terms["total"].backward()
            optimizer.step()

        one_step()
        start = time.perf_counter()
        for _ in range(steps):
            one_step()
        train_s = time.perf_counter() - start
    return {
        "datagen_samples_per_s": samples_made / datagen_s,
        "train_samples_per_s": steps * config.batch_size / train_s,
        "train_step_s_cpu": train_s / steps,
        "train_base_channels": config.base_channels,
    }


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    defaults = TrainConfig()
    parser.add_argument("--variant", choices=sorted(PRIORS), default=defaults.variant)
    parser.add_argument("--data", default=defaults.data, help="dataset root written by datagen")
    parser.add_argument("--train-split", default=defaults.train_split)
    parser.add_argument("--test-split", default=defaults.test_split)
    parser.add_argument("--out", default="", help="final checkpoint (default results/train/<variant>/<variant>.pt)")
    parser.add_argument("--work-dir", default="", help="state.pt, curves.png, result.json (default: beside --out)")
    parser.add_argument("--steps", type=int, default=defaults.steps)
    parser.add_argument("--batch-size", type=int, default=defaults.batch_size, help="global batch size")
    parser.add_argument("--lr", type=float, default=defaults.lr)
    parser.add_argument(
        "--pos-weight", type=float, default=defaults.pos_weight, help="cross-entropy weight of occupied voxels"
    )
    parser.add_argument("--surface-weight", type=float, default=defaults.surface_weight)
    parser.add_argument("--stability-weight", type=float, default=defaults.stability_weight)
    parser.add_argument("--connectivity-weight", type=float, default=defaults.connectivity_weight)
    parser.add_argument(
        "--connectivity-factor",
        type=int,
        default=defaults.connectivity_factor,
        help="coarsening of the grid for the connectivity prior",
    )
    parser.add_argument(
        "--connectivity-endpoints",
        type=int,
        default=defaults.connectivity_endpoints,
        help="existing cells sampled as path endpoints per object",
    )
    parser.add_argument("--base-channels", type=int, default=defaults.base_channels)
    parser.add_argument("--no-augment", action="store_true", help="no random grid rotations/mirrors")
    parser.add_argument("--device", default=defaults.device, help="auto (cuda when present), cpu or cuda")
    parser.add_argument("--threads", type=int, default=defaults.threads, help="CPU threads")
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--checkpoint-every", type=int, default=defaults.checkpoint_every)
    parser.add_argument("--eval-every", type=int, default=defaults.eval_every)
    parser.add_argument("--eval-samples", type=int, default=defaults.eval_samples)
    parser.add_argument(
        "--init-from",
        default="",
        help="start from another run's state.pt (same input "
        "channels: weights, optimiser, step and history) when --work-dir has no state yet",
    )
    parser.add_argument("--save-float32", action="store_true", help="store float32 weights (default float16)")
    parser.add_argument(
        "--final-eval-samples",
        type=int,
        default=defaults.final_eval_samples,
        help="held-out samples for the final metrics (0: all)",
    )
    parser.add_argument(
        "--time-limit-min",
        type=float,
        default=defaults.time_limit_min,
        help="stop after this many minutes of this session and finish (0: no limit)",
    )
    return parser


def config_from_args(args) -> TrainConfig:
    values = {
        field.name: getattr(args, field.name) for field in dataclasses.fields(TrainConfig) if hasattr(args, field.name)
    }
    values["augment"] = not args.no_augment
    values["save_float16"] = not args.save_float32
    return TrainConfig(**values)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = _parser()
    args = parser.parse_args(argv)
    numbers = (
        args.steps,
        args.batch_size,
        args.checkpoint_every,
        args.connectivity_factor,
        args.connectivity_endpoints,
        args.base_channels,
        args.threads,
    )
    if min(numbers) < 1 or args.lr <= 0 or min(args.stability_weight, args.connectivity_weight) < 0:
        parser.error("counts must be >= 1, --lr > 0 and the loss weights >= 0")
    config = config_from_args(args)
    result = train(config, command="train " + shlex.join(argv))
    print(json.dumps(result, indent=1))
    return 0 if not result.get("interrupted") else 130


if __name__ == "__main__":
    raise SystemExit(main())
