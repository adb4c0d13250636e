"""seg_train: train the boundary network on seg_datagen shards; resumable, writes the model card.

Random crops of the working-grid frames (mirrored at random, with brightness and contrast jitter)
are fed to the network; the loss is the class-balanced binary cross-entropy of the outline target
(object pixels within one working-grid pixel of another object, boundary_net.boundary_targets) plus that of
the object mask (its pixels within OBJECT_BAND_PX of an object weighted by --object-band-weight:
that band is where the segmentation uses it). Every --save-every steps the model, the optimiser and
the step go to <out>.state, so a stopped run resumes where it stopped; --minutes bounds the wall
time of one call. At the end the test split is scored (outline precision, recall and F1 at the
network's threshold; the object channel's precision and recall in the band) and <out> (the shipped
weights), <out minus .pt>.md (the model card) and _curves.png are written.
"""

from __future__ import annotations

import argparse
import datetime
import json
import pathlib
import time

import cv2
import numpy as np
from tqdm import tqdm

from arm_core.atomic_io import atomic_write
from arm_segmentation.boundary_net import DEFAULT_CHECKPOINT, BoundaryParams, boundary_features, boundary_targets

OBJECT_BAND_PX = 10  # working-grid pixels: BoundaryParams.fill_reach_px at full resolution


def object_band(objects: np.ndarray, radius_px: int = OBJECT_BAND_PX) -> np.ndarray:
    """HxW bool: pixels within radius_px of an object pixel (the object pixels included)."""
    size = 2 * radius_px + 1
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    return cv2.dilate(objects.astype(np.uint8), disk) > 0


def load_split(root, split: str) -> dict[str, np.ndarray]:
    """All shards of a split stacked: rgb, depth, normals (float32), height, labels."""
    files = sorted((pathlib.Path(root) / split).glob("shard_*.npz"))
    if not files:
        raise FileNotFoundError(f"no shards in {pathlib.Path(root) / split} (run seg_datagen)")
    parts: dict[str, list] = {"rgb": [], "depth": [], "normals": [], "height": [], "labels": []}
    for path in tqdm(files, desc=f"loading {split}", unit="shard"):
        with np.load(path) as data:
            for name in parts:
                parts[name].append(data[name])
    return {name: np.concatenate(values) for name, values in parts.items()}


def sample_arrays(data: dict, index: int, rows: slice, cols: slice, flip: bool):
    """(features (9, h, w), outline (h, w), object (h, w)) of one crop of frame `index`."""
    rgb, depth, height, labels = (data[k][index, rows, cols] for k in ("rgb", "depth", "height", "labels"))
    normals = data["normals"][index, rows, cols].astype(np.float32) / 127.0
    if flip:
        rgb, depth, height, labels, normals = (a[:, ::-1] for a in (rgb, depth, height, labels, normals))
        normals = normals * np.array([-1.0, 1.0, 1.0], dtype=np.float32)
    features = boundary_features(rgb, depth.astype(np.float32), normals, height.astype(np.float32))
    return features, boundary_targets(labels), labels > 0


def _shard_count(root) -> int:
    return len(list((pathlib.Path(root) / "train").glob("shard_*.npz")))


def make_batch(data: dict, rng: np.random.Generator, size: int, crop: tuple[int, int]):
    import torch

    n, height, width = data["labels"].shape
    xs, outlines, objects = [], [], []
    for index in rng.integers(0, n, size):
        y0 = int(rng.integers(0, height - crop[0] + 1))
        x0 = int(rng.integers(0, width - crop[1] + 1))
        features, outline, obj = sample_arrays(
            data, int(index), slice(y0, y0 + crop[0]), slice(x0, x0 + crop[1]), bool(rng.random() < 0.5)
        )
        features[:3] = (features[:3] + 0.5) * rng.uniform(0.7, 1.3) + rng.uniform(-0.1, 0.1) - 0.5
        xs.append(features)
        outlines.append(outline)
        objects.append(obj)
    bands = [object_band(obj) for obj in objects]
    targets = np.stack([np.stack(outlines), np.stack(objects), np.stack(bands)], 1).astype(np.float32)
    return torch.from_numpy(np.stack(xs)), torch.from_numpy(targets)


def loss_fn(logits, targets, outline_weight: float, object_band_weight: float = 1.0):
    """targets (N, 3, H, W): outline, object, object band (object_band)."""
    import torch.nn.functional as F

    weight = 1.0 + (outline_weight - 1.0) * targets[:, :1]
    outline = F.binary_cross_entropy_with_logits(logits[:, :1], targets[:, :1], weight=weight)
    band_weight = 1.0 + (object_band_weight - 1.0) * targets[:, 2:3]
    obj = F.binary_cross_entropy_with_logits(logits[:, 1:2], targets[:, 1:2], weight=band_weight)
    return outline + 0.5 * obj


def evaluate(model, data: dict, threshold: float) -> dict:
    """Outline precision / recall / F1 and object-pixel accuracy over whole test frames."""
    import torch

    model.eval()
    tp = fp = fn = 0
    correct = total = 0
    band_tp = band_fp = band_fn = 0
    height, width = data["labels"].shape[1:]
    with torch.inference_mode():
        for index in range(len(data["labels"])):
            features, outline, obj = sample_arrays(data, index, slice(0, height), slice(0, width), False)
            probability = torch.sigmoid(model(torch.from_numpy(features)[None]))[0].numpy()
            predicted = probability[0] > threshold
            tp += int(np.sum(predicted & outline))
            fp += int(np.sum(predicted & ~outline))
            fn += int(np.sum(~predicted & outline))
            correct += int(np.sum((probability[1] > 0.5) == obj))
            total += obj.size
            seen = (probability[1] > BoundaryParams().fill_threshold) & object_band(obj)
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
        "test_frames": int(len(data["labels"])),
    }


def train(args) -> dict:
    import torch

    from arm_segmentation.boundary_net import build_network

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    out = pathlib.Path(args.out)
    state_path = out.with_suffix(".state")
    data = load_split(args.data, "train")
    model = build_network(args.width)
    optimiser = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, args.lr, total_steps=args.steps, pct_start=0.05)
    step, history = 0, []
    if args.init:
        model.load_state_dict(torch.load(args.init, map_location="cpu", weights_only=False)["model"])
    if state_path.is_file() and not args.restart:
        state = torch.load(state_path, map_location="cpu", weights_only=False)
        model.load_state_dict(state["model"])
        optimiser.load_state_dict(state["optimiser"])
        schedule.load_state_dict(state["schedule"])
        step, history = int(state["step"]), list(state["history"])
    rng = np.random.default_rng([args.seed, step])
    deadline = time.monotonic() + 60.0 * args.minutes
    bar = tqdm(total=args.steps, initial=step, desc="seg_train", unit="step")
    running = None

    def save_state():
        state = {"model": model.state_dict(), "optimiser": optimiser.state_dict(),
                 "schedule": schedule.state_dict(), "step": step, "history": history}  # fmt: skip
        atomic_write(state_path, lambda tmp: torch.save(state, tmp))

    model.train()
    shard_count = _shard_count(args.data)
    while step < args.steps and time.monotonic() < deadline:
        if step % args.reload_every == 0 and _shard_count(args.data) != shard_count:
            shard_count, data = _shard_count(args.data), load_split(args.data, "train")  # seg_datagen still writing
        x, targets = make_batch(data, rng, args.batch, (args.crop_height, args.crop_width))
        loss = loss_fn(model(x), targets, args.outline_weight, args.object_band_weight)
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        optimiser.step()
        schedule.step()
        step += 1
        value = loss.item()
        running = value if running is None else 0.98 * running + 0.02 * value
        bar.update(1)
        bar.set_postfix(loss=f"{running:.4f}")
        if step % 50 == 0:
            history.append((step, running))
        if step % args.save_every == 0:
            save_state()
    bar.close()
    save_state()
    result = {"step": step, "steps": args.steps, "finished": step >= args.steps}
    if step >= args.steps or args.export_unfinished:
        result["test"] = evaluate(model, load_split(args.data, "test"), BoundaryParams().threshold)
        config = {"width": args.width, "steps": step, "batch": args.batch,
                  "crop": [args.crop_height, args.crop_width], "lr": args.lr,
                  "outline_weight": args.outline_weight, "object_band_weight": args.object_band_weight,
                  "train_frames": int(len(data["labels"])),
                  "init": pathlib.Path(args.init).name if args.init else "none"}  # fmt: skip
        payload = {"config": config, "model": model.state_dict(), "test": result["test"]}
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
    axis.set_ylabel("training loss (running mean)")
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
    parser.add_argument("--steps", type=int, default=6000)
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
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--restart", action="store_true", help="ignore a saved state")
    parser.add_argument("--init", default="", help="start from the weights of this state or checkpoint file")
    parser.add_argument("--export-unfinished", action="store_true", help="write the weights even if stopped early")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.batch < 1 or args.minutes <= 0:
        parser.error("--steps, --batch must be >= 1 and --minutes > 0")
    print(json.dumps(train(args)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
