"""Small perceptron classifiers over named features: numpy inference, torch fitting, one file format.

The segmentation's learned decisions (merge_model: two regions are one object; outline_model: a
pixel at an outline belongs to the object) are two-hidden-layer perceptrons over standardised
features, or ensembles of such perceptrons that average their logits (each layer's weights stacked
member by member: (members, in, out)). Weights live in .npz files with the feature names they were
trained on, and a model card (.md) beside them.
"""

from __future__ import annotations

import json
import pathlib

import numpy as np
from tqdm import tqdm

from arm_core.atomic_io import atomic_write

# Rows per matrix product: small enough that OpenBLAS keeps each product on the calling thread. Its
# worker threads, once woken, spin for a while after the product and took about 130 ms of CPU per
# frame from the rest of the segmentation (a 5,000-pixel outline pass) on a 2-core machine.
ROWS_PER_PRODUCT = 256


def perceptron_probability(features, mean, scale, layers) -> np.ndarray:
    """(P,) sigmoid output of the perceptron `layers` [(weights, bias), ...] (ReLU between them) on
    features standardised by mean and scale. Weights (in, out) with bias (out,) are one perceptron;
    (members, in, out) with (members, out) an ensemble, whose output is its members' mean logit."""
    x = (np.asarray(features, dtype=np.float32) - mean) / scale
    out = np.empty(len(x), dtype=np.float32)
    for start in range(0, len(x), ROWS_PER_PRODUCT):
        h = x[start : start + ROWS_PER_PRODUCT]
        for k, (w, b) in enumerate(layers):
            h = h @ w + b[..., None, :]  # an ensemble's members: one small product each
            if k < len(layers) - 1:
                h = np.maximum(h, 0.0)
        logit = h[..., 0]
        logit = logit.mean(axis=0) if logit.ndim == 2 else logit
        out[start : start + len(logit)] = logit
    return 1.0 / (1.0 + np.exp(-np.clip(out, -30.0, 30.0)))


class Perceptron:
    """Perceptron weights loaded from `path`, checked against the feature names they must have been
    trained on; `what` names the classifier in errors. FileNotFoundError when the file is missing,
    ValueError when it is not such weights."""

    def __init__(self, path: str | pathlib.Path, feature_names: tuple[str, ...], what: str):
        path = pathlib.Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{what} weights not found: {path}")
        try:
            with np.load(path, allow_pickle=False) as data:
                names = tuple(str(name) for name in data["feature_names"])
                self.mean, self.scale = data["mean"], data["scale"]
                self.layers = [(data[f"w{k}"], data[f"b{k}"]) for k in range(int(data["n_layers"]))]
        except (KeyError, ValueError, OSError) as error:
            raise ValueError(f"{path} is not {what} weights ({type(error).__name__}: {error})") from error
        if names != tuple(feature_names):
            raise ValueError(f"{path} was trained on other features: {names}")
        self.path = path

    def probability(self, features: np.ndarray) -> np.ndarray:
        """(P,) output probability per feature row."""
        return perceptron_probability(features, self.mean, self.scale, self.layers)


def fit_perceptron(features, target, weight, hidden: int, steps: int, seed: int, batch: int = 0, desc: str = "fit"):
    """(mean, scale, layers) of a perceptron with two hidden layers trained by Adam (learning rate
    3e-3) on binary targets: full batches (batch 0, weight decay 1e-5), or minibatches of `batch`
    rows drawn at random with a cosine-decaying learning rate."""
    import torch

    torch.manual_seed(seed)
    mean = features.mean(axis=0)
    scale = np.maximum(features.std(axis=0), 1e-3)
    x = torch.from_numpy(((features - mean) / scale).astype(np.float32))
    y, w = torch.from_numpy(np.asarray(target, np.float32)), torch.from_numpy(np.asarray(weight, np.float32))
    model = torch.nn.Sequential(
        torch.nn.Linear(x.shape[1], hidden), torch.nn.ReLU(), torch.nn.Linear(hidden, hidden), torch.nn.ReLU(),
        torch.nn.Linear(hidden, 1),
    )  # fmt: skip
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3, weight_decay=0.0 if batch else 1e-5)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, steps) if batch else None
    generator = torch.Generator().manual_seed(seed)
    for _ in tqdm(range(steps), desc=desc, unit="step"):
        rows = torch.randint(0, len(y), (batch,), generator=generator) if batch else slice(None)
        optimiser.zero_grad()
        loss = torch.nn.functional.binary_cross_entropy_with_logits(model(x[rows])[:, 0], y[rows], weight=w[rows])
        loss.backward()
        optimiser.step()
        if schedule is not None:
            schedule.step()
    linear = [m for m in model if isinstance(m, torch.nn.Linear)]
    layers = [(m.weight.detach().numpy().T.copy(), m.bias.detach().numpy().copy()) for m in linear]
    return mean.astype(np.float32), scale.astype(np.float32), layers


def stack_perceptrons(layer_sets) -> list:
    """The ensemble (see perceptron_probability) of the perceptrons `layer_sets`
    [[(weights, bias), ...], ...], which must have the same layer shapes and share one
    standardisation of the features."""
    shapes = [[w.shape for w, _ in layers] for layers in layer_sets]
    if any(s != shapes[0] for s in shapes):
        raise ValueError(f"stack_perceptrons: the perceptrons differ in layer shapes: {shapes}")
    return [
        (np.stack([ls[k][0] for ls in layer_sets]), np.stack([ls[k][1] for ls in layer_sets]))
        for k in range(len(shapes[0]))
    ]


def save_perceptron(path: pathlib.Path, feature_names, mean, scale, layers, title: str, card: dict) -> None:
    """Weights to path (.npz) and a model card titled `title` with `card` as JSON to path.md."""
    arrays = {"feature_names": np.array(feature_names), "mean": mean, "scale": scale, "n_layers": np.array(len(layers))}
    for k, (w, b) in enumerate(layers):
        arrays[f"w{k}"], arrays[f"b{k}"] = w.astype(np.float32), b.astype(np.float32)
    path = pathlib.Path(path)
    atomic_write(path, lambda tmp: np.savez(tmp, **arrays))
    lines = [f"# {title}", "", "```json", json.dumps(card, indent=2), "```", ""]
    atomic_write(path.with_suffix(".md"), lambda tmp: pathlib.Path(tmp).write_text("\n".join(lines)))


_SHARED: dict = {}


def shared_perceptron(factory, enabled: bool, checkpoint: str, default_checkpoint: pathlib.Path):
    """factory(checkpoint) loaded once per (factory, weights file), then shared; None when not
    enabled or when the shipped weights (checkpoint '') are missing. Named weights that are missing
    raise FileNotFoundError; a file that is not such weights raises ValueError."""
    if not enabled:
        return None
    key = (factory, checkpoint or str(default_checkpoint))
    if key not in _SHARED:
        try:
            _SHARED[key] = factory(checkpoint)
        except FileNotFoundError:
            if checkpoint:
                raise
            _SHARED[key] = None
    return _SHARED[key]
