"""Model cards for trained checkpoints, written from what the checkpoint itself records.

    python -m arm_reconstruction.model_cards CHECKPOINT.pt [...] [--note TEXT]

writes ``CHECKPOINT.md`` beside each checkpoint: variant, network, data (seeds, shards, sizes),
steps, wall time, device, loss weights, held-out metrics and the exact training command.
"""

from __future__ import annotations

import argparse
import pathlib

from arm_reconstruction.checkpoint import read_checkpoint
from arm_reconstruction.grid import CHECKPOINT_DEFAULT_K

_METRIC_NAMES = {
    "iou": "voxel IoU (threshold 0.5)",
    "chamfer_m": "voxel Chamfer distance (m)",
    "stable": "statically stable prediction (fraction)",
    "single_component": "single 26-connected component (fraction)",
}
_PRIORS = {
    "baseline": "F1 input only, reconstruction loss (GenRe-style)",
    "arm-c-s": "four-channel input, reconstruction loss",
    "arm-c": "four-channel input, reconstruction loss + stability prior",
    "arm": "four-channel input, reconstruction loss + stability prior + connectivity prior",
}


def model_card(checkpoint_path, note: str = "") -> str:
    """Markdown model card of one checkpoint."""
    path = pathlib.Path(checkpoint_path)
    payload = read_checkpoint(path)
    config, extra = payload["config"], payload.get("extra", {})
    training = config.get("training", {})
    metrics = extra.get("heldout_metrics", {})
    variant = config["variant"]
    lines = [
        f"# `{variant}` reconstruction network",
        "",
        f"{_PRIORS.get(variant, variant)}.",
        "",
        "| | |",
        "| --- | --- |",
        f"| file | `{path.name}` ({path.stat().st_size / 1e6:.1f} MB) |",
        f"| network | {config['architecture']}, {config['in_channels']} input channels, "
        f"{config['resolution']}^3 grid, {config['base_channels']} base channels, weights stored as "
        f"{extra.get('weights_dtype', 'float32')} |",
        f"| grid | side {config.get('grid_k', CHECKPOINT_DEFAULT_K):g} x the object's observed diameter "
        "(more where its seen top needs it) |",
        f"| training data | {extra.get('train_samples', '?')} samples from {extra.get('train_shards', '?')} "
        f"shards of split `{training.get('train_split', '?')}` (training categories) in `{training.get('data', '?')}`"
        f"{_seed_text(extra.get('train_seeds'))} |",
        f"| held-out data | {extra.get('test_samples', '?')} samples from {extra.get('test_shards', '?')} shards of "
        f"split `{training.get('test_split', '?')}` (held-out categories){_seed_text(extra.get('test_seeds'))} |",
        f"| steps | {extra.get('steps', '?')} x batch {training.get('batch_size', '?')} "
        f"({extra.get('samples_seen', '?')} samples seen), Adam lr {training.get('lr', '?')} |",
        f"| loss weights | pos {training.get('pos_weight')}, surface {training.get('surface_weight')}, "
        f"stability {training.get('stability_weight') if 'stability' in _PRIORS.get(variant, '') else '-'}, "
        f"connectivity {training.get('connectivity_weight') if variant == 'arm' else '-'}"
        f"{_connectivity_text(training) if variant == 'arm' else ''} |",
        f"| wall time | {float(extra.get('train_wall_s', 0.0)) / 60:.1f} min of training steps |",
        f"| device | {extra.get('device', '?')} ({extra.get('processes', 1)} process(es)) |",
        f"| training seed | {training.get('seed', '?')} |",
        "",
        f"## Held-out metrics ({metrics.get('samples', '?')} samples; occluded: visible fraction < 0.7, "
        f"{metrics.get('occluded_samples', '?')} samples)",
        "",
        "| metric | all | occluded |",
        "| --- | --- | --- |",
    ]
    for key, name in _METRIC_NAMES.items():
        if key in metrics:
            lines.append(f"| {name} | {_number(metrics.get(key))} | {_number(metrics.get(f'{key}_occluded'))} |")
    lines += [
        "",
        "## Command",
        "",
        "```",
        extra.get("command", "?"),
        "```",
    ]
    if note:
        lines += ["", "## Notes", "", note]
    return "\n".join(lines) + "\n"


def _seed_text(seeds) -> str:
    return f", shard seeds {seeds[0]}..{seeds[1]}" if seeds else ""


def _connectivity_text(training: dict) -> str:
    return (
        f" (grid coarsened by {training.get('connectivity_factor')}, "
        f"{training.get('connectivity_endpoints')} endpoints)"
    )


def _number(value) -> str:
    return "-" if value is None else f"{value:.4f}"


def write_model_card(checkpoint_path, note: str = "") -> pathlib.Path:
    path = pathlib.Path(checkpoint_path).with_suffix(".md")
    path.write_text(model_card(checkpoint_path, note))
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="write <checkpoint>.md model cards")
    parser.add_argument("checkpoints", nargs="+")
    parser.add_argument("--note", default="", help="extra paragraph (for example what the GPU was used for)")
    args = parser.parse_args(argv)
    for checkpoint in args.checkpoints:
        print(write_model_card(checkpoint, args.note))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
