"""The training loop: resumable from <work-dir>/state.pt (model, optimiser, random state, history,
config), stopped cleanly by SIGTERM or Ctrl-C, evaluated and saved with save_checkpoint at the end."""

from __future__ import annotations

import dataclasses
import json
import pathlib
import signal
import time

import numpy as np
import torch
from tqdm import tqdm

from arm_core.atomic_io import atomic_write
from arm_reconstruction.checkpoint import CHECKPOINT_FORMAT, read_checkpoint, save_checkpoint
from arm_reconstruction.network import VARIANTS, build_model, select_input_channels
from arm_training.reconstruction.dataset import VoxelDataset, random_symmetry
from arm_training.reconstruction.training.config import TrainConfig, losses_for_batch
from arm_training.reconstruction.training.distributed import torchrun_ranks, training_device
from arm_training.reconstruction.training.evaluation import evaluate
from arm_training.reconstruction.training.plots import plot_curves


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


def _is_shipped_checkpoint(path: pathlib.Path) -> bool:
    payload = torch.load(path, map_location="cpu", weights_only=False)
    return isinstance(payload, dict) and payload.get("format") == CHECKPOINT_FORMAT


def _start_from_checkpoint(path: pathlib.Path, model: torch.nn.Module, variant: str) -> tuple:
    """Fine-tuning from a saved checkpoint (for example a shipped one): its weights, step count,
    thinned loss history and evaluations; a fresh optimiser. -> (step, history, evaluations, elapsed_s)."""
    payload = read_checkpoint(path)
    if VARIANTS[payload["config"]["variant"]] != VARIANTS[variant]:
        raise SystemExit(f"--init-from {path}: variant {payload['config']['variant']} reads other input channels")
    model.load_state_dict({key: value.float() for key, value in payload["state_dict"].items()})
    extra = payload.get("extra", {})
    history, evaluations = list(extra.get("loss_history", [])), list(extra.get("evaluations", []))
    return int(extra.get("steps", 0)), history, evaluations, float(extra.get("train_wall_s", 0.0))


def train(config: TrainConfig, command: str = "", progress: bool = True) -> dict:
    """Run (or resume) a training; returns the final held-out metrics and timing."""
    rank, world, local_rank = torchrun_ranks()
    if world > 1:
        backend = "nccl" if config.device != "cpu" and torch.cuda.is_available() else "gloo"
        torch.distributed.init_process_group(backend)
    device = training_device(config.device, local_rank)
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
    if start_path is not None and start_path != state_path and _is_shipped_checkpoint(start_path):
        step, history, evaluations, elapsed_s = _start_from_checkpoint(start_path, model, config.variant)
    elif start_path is not None:
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
        augment_generator.set_state(state["augment_rng"].cpu())
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
            batch = train_set.batch(rng.choice(len(train_set), per_process_batch, replace=False), device)
            if config.augment:
                batch = random_symmetry(batch, augment_generator)
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
        config={"training": dataclasses.asdict(config), "grid_k": train_set.k},
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
