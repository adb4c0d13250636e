"""seg_train: train the boundary network on seg_datagen shards; resumable, writes the model card.

Every frame's network input and targets are computed once when the shards load (in --workers
processes) and kept as tensors on --device; batches are random crops of them, mirrored at random,
with brightness and contrast jitter, cut on that device (so a GPU is not starved by batch making).
The loss is the class-balanced binary cross-entropy of the outline target (object pixels within
one working-grid pixel of another object, boundary_net.boundary_targets) plus that of the object
mask (its pixels within OBJECT_BAND_PX of an object weighted by --object-band-weight: that band is
where the segmentation uses it). Every --save-every steps the model, the optimiser and the step go
to <out>.state, so a stopped run resumes where it stopped; --minutes bounds the wall time of one
call. At the end the test split is scored (outline precision, recall and F1 at the network's
threshold; the object channel's precision and recall in the band) and <out> (the shipped weights),
<out minus .pt>.md (the model card) and _curves.png are written.
"""

from __future__ import annotations

import argparse
import datetime
import json
import pathlib
import time
from concurrent.futures import ProcessPoolExecutor

import cv2
import numpy as np
from tqdm import tqdm

from arm_core.atomic_io import atomic_write
from arm_segmentation.boundary_net import DEFAULT_CHECKPOINT, BoundaryParams, boundary_features, boundary_targets

OUTLINE_THRESHOLD = 0.5  # outline probability scored as an outline in the test figures
OBJECT_BAND_PX = 10  # working-grid pixels: BoundaryParams.fill_reach_px at full resolution
NORMAL_X_CHANNEL = 5  # boundary_features: rgb (0-2), depth, depth valid, normals (5-7), height


def object_band(objects: np.ndarray, radius_px: int = OBJECT_BAND_PX) -> np.ndarray:
    """HxW bool: pixels within radius_px of an object pixel (the object pixels included)."""
    size = 2 * radius_px + 1
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    return cv2.dilate(objects.astype(np.uint8), disk) > 0


def frame_arrays(rgb, depth, normals, height, labels) -> tuple[np.ndarray, np.ndarray]:
    """One stored frame as (features (9, H, W) float16, targets (3, H, W) uint8: outline, object,
    object band)."""
    features = boundary_features(rgb, depth.astype(np.float32), normals.astype(np.float32) / 127.0,
                                 height.astype(np.float32))  # fmt: skip
    objects = labels > 0
    targets = np.stack([boundary_targets(labels), objects, object_band(objects)]).astype(np.uint8)
    return features.astype(np.float16), targets


def _load_shard(path: pathlib.Path) -> tuple[np.ndarray, np.ndarray]:
    with np.load(path) as data:
        frames = [frame_arrays(*(data[k][i] for k in ("rgb", "depth", "normals", "height", "labels")))
                  for i in range(len(data["labels"]))]  # fmt: skip
    return np.stack([f for f, _ in frames]), np.stack([t for _, t in frames])


def load_split(root, split: str, workers: int = 1) -> dict[str, np.ndarray]:
    """All frames of a split: features (N, 9, H, W) float16 and targets (N, 3, H, W) uint8."""
    files = sorted((pathlib.Path(root) / split).glob("shard_*.npz"))
    if not files:
        raise FileNotFoundError(f"no shards in {pathlib.Path(root) / split} (run seg_datagen)")
    bar = {"total": len(files), "desc": f"loading {split}", "unit": "shard"}
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            parts = list(tqdm(pool.map(_load_shard, files), **bar))
    else:
        parts = list(tqdm(map(_load_shard, files), **bar))
    return {"features": np.concatenate([f for f, _ in parts]), "targets": np.concatenate([t for _, t in parts])}


def _shard_count(root) -> int:
    return len(list((pathlib.Path(root) / "train").glob("shard_*.npz")))


def crop_batch(features, targets, generator, size: int, crop: tuple[int, int]):
    """(x (size, 9, h, w) float32, targets (size, 3, h, w) float32): random crops of random frames
    of the (N, C, H, W) tensors, on their device; half mirrored (the normal's x negated), colour
    contrast and brightness jittered."""
    import torch

    device = features.device
    n, _, height, width = features.shape

    def draw(high: int) -> torch.Tensor:
        return torch.randint(high, (size,), generator=generator, device=device)

    index, y0, x0 = draw(n), draw(height - crop[0] + 1), draw(width - crop[1] + 1)
    rows = y0[:, None] + torch.arange(crop[0], device=device)
    cols = x0[:, None] + torch.arange(crop[1], device=device)
    flip = torch.rand(size, generator=generator, device=device) < 0.5
    cols = torch.where(flip[:, None], cols.flip(1), cols)
    pick = (index[:, None, None], slice(None), rows[:, :, None], cols[:, None, :])
    x = features[pick].permute(0, 3, 1, 2).float()  # advanced indices first: (size, h, w, C)
    y = targets[pick].permute(0, 3, 1, 2).float()
    x[:, NORMAL_X_CHANNEL] *= torch.where(flip, -1.0, 1.0)[:, None, None]
    jitter = torch.rand(2, size, 1, 1, 1, generator=generator, device=device)
    x[:, :3] = (x[:, :3] + 0.5) * (0.7 + 0.6 * jitter[0]) + (0.2 * jitter[1] - 0.1) - 0.5
    return x.contiguous(), y.contiguous()


def loss_fn(logits, targets, outline_weight: float, object_band_weight: float = 1.0):
    """targets (N, 3, H, W): outline, object, object band (object_band)."""
    import torch.nn.functional as F

    weight = 1.0 + (outline_weight - 1.0) * targets[:, :1]
    outline = F.binary_cross_entropy_with_logits(logits[:, :1], targets[:, :1], weight=weight)
    band_weight = 1.0 + (object_band_weight - 1.0) * targets[:, 2:3]
    obj = F.binary_cross_entropy_with_logits(logits[:, 1:2], targets[:, 1:2], weight=band_weight)
    return outline + 0.5 * obj


def evaluate(model, data: dict, threshold: float, device: str = "cpu") -> dict:
    """Outline precision / recall / F1 and object-pixel accuracy over whole test frames."""
    import torch

    model.eval()
    tp = fp = fn = 0
    correct = total = 0
    band_tp = band_fp = band_fn = 0
    with torch.inference_mode():
        for features, targets in zip(data["features"], data["targets"], strict=True):
            x = torch.from_numpy(features.astype(np.float32))[None].to(device)
            probability = torch.sigmoid(model(x))[0].cpu().numpy()
            outline, obj, band = targets.astype(bool)
            predicted = probability[0] > threshold
            tp += int(np.sum(predicted & outline))
            fp += int(np.sum(predicted & ~outline))
            fn += int(np.sum(~predicted & outline))
            correct += int(np.sum((probability[1] > 0.5) == obj))
            total += obj.size
            seen = (probability[1] > BoundaryParams().fill_threshold) & band
            band_tp += int(np.sum(seen & obj))
            band_fp += int(np.sum(seen & ~obj))
            band_fn += int(np.sum(~seen & obj))
    model.train()
    precision = tp / max(tp + fp, 1)
    recall = tp / max(tp + fn, 1)
    return {
        "outline_precision": round(precision, 4),
        "outline_recall": round(recall, 4),
        "outline_f1": round(2 * precision * recall / max(precision + recall, 1e-9), 4),
        "object_pixel_accuracy": round(correct / max(total, 1), 4),
        # the object channel at the fill threshold, on pixels within OBJECT_BAND_PX of an object
        "object_band_precision": round(band_tp / max(band_tp + band_fp, 1), 4),
        "object_band_recall": round(band_tp / max(band_tp + band_fn, 1), 4),
        "test_frames": int(len(data["targets"])),
    }


def training_step(model, optimiser, features, targets, generator, args):
    """One optimiser step on a batch of crops (crop_batch); returns the loss (a tensor, not synced)."""
    x, y = crop_batch(features, targets, generator, args.batch, (args.crop_height, args.crop_width))
    loss = loss_fn(model(x), y, args.outline_weight, args.object_band_weight)
    optimiser.zero_grad(set_to_none=True)
    loss.backward()
    optimiser.step()
    return loss


def step_seconds(model, features, targets, args, steps: int = 30) -> float:
    """Seconds per training step, timed on a copy of the model (the model is left untouched)."""
    import copy

    import torch

    trial = copy.deepcopy(model)
    optimiser = torch.optim.AdamW(trial.parameters(), lr=args.lr)
    generator = torch.Generator(device=features.device)
    for index in range(steps + 5):  # 5 untimed warm-up steps
        if index == 5:
            if features.device.type == "cuda":
                torch.cuda.synchronize(features.device)
            began = time.perf_counter()
        loss = training_step(trial, optimiser, features, targets, generator, args)
    loss.item()
    return (time.perf_counter() - began) / steps


def train(args) -> dict:
    import torch

    from arm_segmentation.boundary_net import build_network

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    out = pathlib.Path(args.out)
    state_path = out.with_suffix(".state")

    def load_train():
        data = load_split(args.data, "train", args.workers)
        return (torch.from_numpy(data["features"]).to(device), torch.from_numpy(data["targets"]).to(device))

    start = time.monotonic()
    features, targets = load_train()
    model = build_network(args.width).to(device)
    state = None
    if state_path.is_file() and not args.restart:
        state = torch.load(state_path, map_location=device, weights_only=False)
        args.steps = int(state.get("steps", args.steps))
    elif args.steps == 0:
        seconds = 60.0 * args.minutes - (time.monotonic() - start)
        args.steps = max(50, int(0.8 * seconds / step_seconds(model, features, targets, args)))  # margin for load
        print(f"seg_train: {args.steps} steps fit in the {seconds:.0f} s left")
    optimiser = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, args.lr, total_steps=args.steps, pct_start=0.05)
    step, history = 0, []
    if args.init:
        model.load_state_dict(torch.load(args.init, map_location=device, weights_only=False)["model"])
    if state is not None:
        model.load_state_dict(state["model"])
        optimiser.load_state_dict(state["optimiser"])
        schedule.load_state_dict(state["schedule"])
        step, history = int(state["step"]), list(state["history"])
    generator = torch.Generator(device=device)
    generator.manual_seed(args.seed * 1_000_003 + step)
    deadline = start + 60.0 * args.minutes
    bar = tqdm(total=args.steps, initial=step, desc="seg_train", unit="step")
    window_loss, window_steps = 0.0, 0  # summed on the device, read every 50 steps

    def save_state():
        state = {"model": model.state_dict(), "optimiser": optimiser.state_dict(),
                 "schedule": schedule.state_dict(), "step": step, "steps": args.steps, "history": history}  # fmt: skip
        atomic_write(state_path, lambda tmp: torch.save(state, tmp))

    model.train()
    shard_count = _shard_count(args.data)
    while step < args.steps and time.monotonic() < deadline:
        if step % args.reload_every == 0 and _shard_count(args.data) != shard_count:
            shard_count, (features, targets) = _shard_count(args.data), load_train()  # seg_datagen still writing
        loss = training_step(model, optimiser, features, targets, generator, args)
        schedule.step()
        step += 1
        bar.update(1)
        window_loss, window_steps = window_loss + loss.detach(), window_steps + 1
        if step % 50 == 0 or step == args.steps:
            mean = float(window_loss) / window_steps  # a device sync: not every step
            window_loss, window_steps = 0.0, 0
            bar.set_postfix(loss=f"{mean:.4f}")
            history.append((step, mean))
        if step % args.save_every == 0:
            save_state()
    bar.close()
    save_state()
    result = {"step": step, "steps": args.steps, "finished": step >= args.steps}
    if step >= args.steps or args.export_unfinished:
        test = load_split(args.data, "test", args.workers)
        result["test"] = evaluate(model, test, OUTLINE_THRESHOLD, device)
        config = {"width": args.width, "steps": step, "batch": args.batch,
                  "crop": [args.crop_height, args.crop_width], "lr": args.lr,
                  "outline_weight": args.outline_weight, "object_band_weight": args.object_band_weight,
                  "train_frames": int(len(targets)),
                  "init": pathlib.Path(args.init).name if args.init else "none"}  # fmt: skip
        weights = {name: value.cpu() for name, value in model.state_dict().items()}
        payload = {"config": config, "model": weights, "test": result["test"]}
        atomic_write(out, lambda tmp: torch.save(payload, tmp))
        write_model_card(out, config, result["test"], history)
    return result


def write_model_card(out: pathlib.Path, config: dict, test: dict, history: list) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(5, 3))
    if history:
        steps, losses = zip(*history, strict=True)
        axis.plot(steps, losses)
    axis.set_xlabel("step")
    axis.set_ylabel("training loss (mean of 50 steps)")
    figure.tight_layout()
    figure.savefig(out.with_name(out.stem + "_curves.png"), dpi=100)
    plt.close(figure)
    lines = [
        "# Boundary network (arm_segmentation)",
        "",
        f"Written {datetime.date.today().isoformat()} by `seg_train`. Input: 9 working-grid channels (colour, "
        "smoothed depth, depth valid, normals, height above the support); output: object-outline and "
        "object-pixel logits. Trained on `seg_datagen` frames of the training categories (4 of 5 scenes "
        "realistic domain, 1 plain); scored on whole frames of the held-out categories.",
        "",
        "| setting | value |",
        "|---|---|",
        *[f"| {k} | {v} |" for k, v in config.items()],
        "",
        "| test figure | value |",
        "|---|---|",
        *[f"| {k} | {v} |" for k, v in test.items()],
        "",
        f"![curves]({out.stem}_curves.png)",
    ]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="data/seg_boundary", help="seg_datagen root (train/ and test/)")
    parser.add_argument("--out", default=str(DEFAULT_CHECKPOINT), help="weights to write (.pt)")
    parser.add_argument("--steps", type=int, default=6000, help="0: as many as --minutes allows (timed first)")
    parser.add_argument("--minutes", type=float, default=60.0, help="wall-time limit of this call")
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--crop-height", type=int, default=128)
    parser.add_argument("--crop-width", type=int, default=160)
    parser.add_argument("--width", type=int, default=8, help="channels at full working resolution")
    parser.add_argument("--lr", type=float, default=3e-3)
    parser.add_argument("--outline-weight", type=float, default=4.0, help="loss weight of outline pixels")
    parser.add_argument(
        "--object-band-weight",
        type=float,
        default=1.0,
        help="loss weight of object-channel pixels within OBJECT_BAND_PX of an object",
    )
    parser.add_argument("--save-every", type=int, default=100)
    parser.add_argument("--reload-every", type=int, default=400, help="steps between looks for new shards")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--workers", type=int, default=1, help="processes that load the shards")
    parser.add_argument("--device", default="cpu", help="torch device: cpu, cuda, cuda:1, ...")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--restart", action="store_true", help="ignore a saved state")
    parser.add_argument("--init", default="", help="start from the weights of this state or checkpoint file")
    parser.add_argument("--export-unfinished", action="store_true", help="write the weights even if stopped early")
    args = parser.parse_args(argv)
    if args.steps < 0 or args.batch < 1 or args.minutes <= 0:
        parser.error("--steps must be >= 0, --batch >= 1 and --minutes > 0")
    print(json.dumps(train(args)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
