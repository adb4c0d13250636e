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
import shlex
import sys

from arm_training.reconstruction.training.config import PRIORS, TrainConfig
from arm_training.reconstruction.training.loop import train


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
        help="when --work-dir has no state yet, start from another run's state.pt (weights, optimiser, "
        "step and history) or from a checkpoint such as a shipped one (weights, step and history; a fresh "
        "optimiser); the same input channels either way",
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
