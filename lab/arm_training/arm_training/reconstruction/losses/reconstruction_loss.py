"""GenRe-style reconstruction loss: weighted voxel cross-entropy plus a surface term.

GenRe (Zhang et al. 2018) trains its refinement network with a voxel cross-entropy and a surface loss
``BCE(sigmoid(x) * y_surface, y_surface)``, i.e. ``-log sigmoid(x)`` on the ground-truth surface shell.
Here the target is the solid occupancy (physics needs solids), the shell is the solid minus its
erosion, and the occupied voxels can be up-weighted (``pos_weight``) because they are sparse.
All grids are ``[B, d, d, d]``; the network outputs logits.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def surface_shell(occupancy: torch.Tensor, thickness_voxels: int = 2) -> torch.Tensor:
    """Occupied voxels within ``thickness_voxels`` (26-neighbourhood steps) of empty space.

    Voxels outside the grid count as empty. Returns a float tensor shaped like ``occupancy``.
    """
    solid = (occupancy >= 0.5).float().unsqueeze(1)
    eroded = solid
    for _ in range(thickness_voxels):
        eroded = -F.max_pool3d(-F.pad(eroded, (1, 1, 1, 1, 1, 1), value=0.0), 3, stride=1)
    return (solid - eroded).clamp_min(0.0).squeeze(1)


def reconstruction_loss(
    logits: torch.Tensor,
    target_occupancy: torch.Tensor,
    pos_weight: float = 1.0,
    surface_weight: float = 1.0,
    shell_thickness_voxels: int = 2,
) -> torch.Tensor:
    """Mean weighted cross-entropy over all voxels plus ``surface_weight`` times the surface term.

    ``target_occupancy`` is in [0, 1]. ``pos_weight`` multiplies the loss of occupied voxels.
    The surface term is the mean over all voxels of ``shell * -log sigmoid(logits)``, as in GenRe.
    Returns a scalar.
    """
    target = target_occupancy.to(logits.dtype)
    weight = torch.as_tensor(pos_weight, dtype=logits.dtype, device=logits.device)
    cross_entropy = F.binary_cross_entropy_with_logits(logits, target, pos_weight=weight)
    shell = surface_shell(target, shell_thickness_voxels)
    surface = (shell * F.softplus(-logits)).mean()
    return cross_entropy + surface_weight * surface
