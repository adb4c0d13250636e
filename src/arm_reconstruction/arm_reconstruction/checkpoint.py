"""Checkpoints that carry their configuration and a checksum, validated on load.

File layout (torch.save of a dict, loaded with weights_only=True):
  format: CHECKPOINT_FORMAT, config: {architecture, variant, in_channels, resolution, base_channels, ...},
  state_dict: tensors, extra: caller's metadata (plain types), sha256: digest of config + tensors.
"""

import hashlib
import json
import pathlib

import numpy as np
import torch

from arm_core.atomic_io import atomic_write

from .grid import CHECKPOINT_DEFAULT_K
from .network import ARCHITECTURE, VARIANTS, build_model, model_config, resolve_device

CHECKPOINT_FORMAT = "arm-reconstruction-checkpoint-v1"
CHECKPOINT_DIR = pathlib.Path(__file__).resolve().parent / "checkpoints"
REQUIRED_CONFIG = ("architecture", "variant", "in_channels", "resolution", "base_channels")


class CheckpointError(RuntimeError):
    """A checkpoint is missing, corrupt, truncated, tampered with or does not match what was asked."""


def default_checkpoint_path(variant: str) -> pathlib.Path:
    """Shipped checkpoint of a network variant: <package>/checkpoints/<variant>.pt."""
    return CHECKPOINT_DIR / f"{variant}.pt"


def _digest(config: dict, state_dict: dict) -> str:
    sha = hashlib.sha256(json.dumps(config, sort_keys=True, default=str).encode())
    for name in sorted(state_dict):
        tensor = state_dict[name].detach().cpu().contiguous()
        sha.update(name.encode())
        sha.update(str(tuple(tensor.shape)).encode() + str(tensor.dtype).encode())
        sha.update(tensor.view(-1).view(torch.uint8).numpy().tobytes() if tensor.numel() else b"")
    return sha.hexdigest()


def _plain(value):
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return str(value)


def save_checkpoint(path, model: torch.nn.Module, config: dict | None = None, extra: dict | None = None) -> None:
    """Write model weights with their config (the model's own config updated with `config`) and
    `extra` (training metadata: plain types). Atomic: a crash never leaves a half-written file."""
    full_config = model_config(model)
    for key, value in _plain(config or {}).items():
        if key in REQUIRED_CONFIG and value != full_config[key]:
            raise CheckpointError(f"config {key}={value!r} contradicts the model ({full_config[key]!r})")
        full_config[key] = value
    state_dict = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
    payload = {
        "format": CHECKPOINT_FORMAT,
        "config": full_config,
        "state_dict": state_dict,
        "extra": _plain(extra or {}),
        "sha256": _digest(full_config, state_dict),
    }
    atomic_write(path, lambda tmp: torch.save(payload, tmp))


def read_checkpoint(path) -> dict:
    """Load and verify a checkpoint file's payload (format, config, checksum) without building a model."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint not found: {path}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:
        raise CheckpointError(f"checkpoint {path} is corrupt or truncated: {type(error).__name__}: {error}") from None
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path} is not an ARM reconstruction checkpoint (format {CHECKPOINT_FORMAT})")
    config, state_dict = payload.get("config"), payload.get("state_dict")
    if not isinstance(config, dict) or not isinstance(state_dict, dict):
        raise CheckpointError(f"checkpoint {path} lacks its config or weights")
    missing = [key for key in REQUIRED_CONFIG if key not in config]
    if missing:
        raise CheckpointError(f"checkpoint {path} config lacks {missing}")
    if _digest(config, state_dict) != payload.get("sha256"):
        raise CheckpointError(f"checkpoint {path} failed its checksum: the file was modified or damaged")
    if config["architecture"] != ARCHITECTURE:
        raise CheckpointError(
            f"checkpoint {path} has architecture {config['architecture']!r}, expected {ARCHITECTURE!r}"
        )
    variant = config["variant"]
    if variant not in VARIANTS:
        raise CheckpointError(f"checkpoint {path} has unknown variant {variant!r}")
    if config["in_channels"] != VARIANTS[variant]:
        raise CheckpointError(
            f"checkpoint {path}: variant {variant!r} needs {VARIANTS[variant]} input channels, config says "
            f"{config['in_channels']}"
        )
    return payload


def load_checkpoint(
    path,
    device: str | torch.device = "cpu",
    expected_variant: str | None = None,
    expected_resolution: int | None = None,
) -> tuple[torch.nn.Module, dict]:
    """-> (model in eval mode on device, config). Raises CheckpointError on a missing, corrupt,
    truncated or tampered file, or when the variant or resolution differs from the expected one."""
    payload = read_checkpoint(path)
    config = payload["config"]
    if expected_variant is not None and config["variant"] != expected_variant:
        raise CheckpointError(f"checkpoint {path} holds variant {config['variant']!r}, expected {expected_variant!r}")
    if expected_resolution is not None and int(config["resolution"]) != int(expected_resolution):
        raise CheckpointError(
            f"checkpoint {path} was trained at resolution {config['resolution']}, expected {expected_resolution}"
        )
    try:
        model = build_model(config["variant"], int(config["resolution"]), int(config["base_channels"]))
        model.load_state_dict(payload["state_dict"], strict=True)
    except (RuntimeError, ValueError, TypeError) as error:
        raise CheckpointError(f"checkpoint {path} weights do not fit its config: {error}") from None
    try:
        model.to(resolve_device(device))
    except ValueError as error:
        raise CheckpointError(str(error)) from None
    model.eval()
    model.grid_k = float(config.get("grid_k", CHECKPOINT_DEFAULT_K))  # the grid it was trained on
    return model, dict(config, extra=payload.get("extra", {}))
