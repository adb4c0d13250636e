"""Stability prior P(E(v)) of ARM (paper Sec. 3.2, appendix A) with its approximate gradient.

Grids are ``[B, X, Y, Z]`` in voxel units with +Z up; the layer ``z = 0`` rests on the table, so its
voxels are supported from below by the table. ``V = sigmoid(logits)`` is the object's occupancy.

For each of ``|S|`` horizontal directions ``s`` a voxel ``i`` holds the object up against tipping
towards ``s`` when it exists, lies beyond the centre of mass along ``s`` and rests on support:

    u_s  = prod_i [1 - V(i) P(i^s > M^s) h_s(i)]           probability of tipping towards s
    P(E) = prod_s (1 - u_s)

``h_s(i) = 1 - prod_{i' in H_s(i)} (1 - V_other(i'))`` with ``H_s(i)`` the voxel directly below ``i``
(the table below layer 0) and the voxel beside ``i`` in direction ``s`` (leaning against it).
``P(i^s > M^s)`` uses a normal approximation of the projected centre of mass
``M^s = sum_i i^s v(i) / sum_i v(i)`` (delta method: mean ``mu_s``, std ``sigma_s``).

Backward (appendix A): the CDF term is held constant and, against underflow, the other voxels enter
the leave-one-out product only when they exist (``V >= 0.5``) and their support is thresholded:

    d log P(E) / dV(i) = sum_s P(i^s > M^s) h^_s(i) prod_{o != i}[1 - P(o^s > M^s) 1{V(o)>=.5} h^_s(o)]
                         / (1 - u_s)

The appendix leaves open which ``u_s`` divides; with the thresholded one it is 0/0 for an object
with no support at all, so the continuous ``u_s`` of the forward pass is used (for an unsupported
object the term then becomes ``d log P(supported along s) / dV(i)``). The chain rule through the
sigmoid multiplies by ``V (1 - V)``; the gradient is masked to unobserved voxels (F4) and scaled by
``grad_output``.
"""

from __future__ import annotations

import math

import torch

N_DIRECTIONS = 25
_TINY = 1e-30


def horizontal_directions(n_directions: int = N_DIRECTIONS, device=None) -> torch.Tensor:
    """``[n, 2]`` unit vectors (x, y) at evenly spaced angles ``2 pi k / n``."""
    angles = torch.arange(n_directions, dtype=torch.float64) * (2.0 * math.pi / n_directions)
    return torch.stack([torch.cos(angles), torch.sin(angles)], dim=1).to(device=device, dtype=torch.float32)


def _shift_xy(grid: torch.Tensor, dx: int, dy: int) -> torch.Tensor:
    """``out[b, x, y, z] = grid[b, x + dx, y + dy, z]`` with zeros outside the grid."""
    out = torch.zeros_like(grid)
    size_x, size_y = grid.shape[1], grid.shape[2]
    dst_x = slice(max(0, -dx), size_x - max(0, dx))
    src_x = slice(max(0, dx), size_x - max(0, -dx))
    dst_y = slice(max(0, -dy), size_y - max(0, dy))
    src_y = slice(max(0, dy), size_y - max(0, -dy))
    out[:, dst_x, dst_y] = grid[:, src_x, src_y]
    return out


def support_probability(other_occupancy: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """``h_s(i)`` as ``[B, S, X, Y, Z]`` from the other objects' occupancy and the table.

    ``H_s(i)`` = {voxel below ``i`` (the table for z = 0), voxel beside ``i`` at the grid step nearest
    to direction ``s``}.
    """
    steps, step_of_direction = _direction_steps(directions)
    per_step = _support_per_step(other_occupancy.float(), steps)
    return per_step[:, step_of_direction]


def _direction_steps(directions: torch.Tensor) -> tuple[list[tuple[int, int]], torch.Tensor]:
    rounded = [tuple(step) for step in torch.round(directions).to(torch.int64).tolist()]
    steps = sorted(set(rounded))
    step_of_direction = torch.tensor([steps.index(step) for step in rounded], device=directions.device)
    return steps, step_of_direction


def _support_per_step(other: torch.Tensor, steps: list[tuple[int, int]]) -> torch.Tensor:
    """``[B, K, X, Y, Z]`` support probability for each distinct horizontal grid step."""
    below = torch.ones_like(other)
    below[..., 1:] = other[..., :-1]
    beside = torch.stack([_shift_xy(other, dx, dy) for dx, dy in steps], dim=1)
    return 1.0 - (1.0 - below.unsqueeze(1)) * (1.0 - beside)


def _column_projection(size_x: int, size_y: int, directions: torch.Tensor) -> torch.Tensor:
    """``[S, X, Y]`` projection of voxel-column centres onto each direction (voxel units)."""
    xs = torch.arange(size_x, device=directions.device, dtype=torch.float32) + 0.5
    ys = torch.arange(size_y, device=directions.device, dtype=torch.float32) + 0.5
    return directions[:, 0, None, None] * xs[None, :, None] + directions[:, 1, None, None] * ys[None, None, :]


def beyond_centre_of_mass_probability(
    occupancy: torch.Tensor, directions: torch.Tensor, sigma_floor_voxels: float = 0.25
) -> torch.Tensor:
    """``P(i^s > M^s(v))`` per voxel column, ``[B, S, X, Y]`` (it does not depend on z).

    ``M^s = sum_i i^s v(i) / sum_i v(i)`` with Bernoulli ``v(i) ~ V(i)``, approximated by a normal with
    mean ``sum i^s V / sum V`` and (delta method) variance ``sum (i^s - mu)^2 V (1 - V) / (sum V)^2``.
    """
    v = occupancy.float()
    projection = _column_projection(v.shape[1], v.shape[2], directions)
    column_mass = v.sum(dim=3)
    column_variance = (v * (1.0 - v)).sum(dim=3)
    mass = column_mass.sum(dim=(1, 2)).clamp_min(1e-6)
    mean = torch.einsum("bxy,sxy->bs", column_mass, projection) / mass[:, None]
    centred = projection.unsqueeze(0) - mean[:, :, None, None]
    variance = torch.einsum("bsxy,bxy->bs", centred.square(), column_variance) / mass[:, None].square()
    sigma = variance.sqrt().clamp_min(sigma_floor_voxels)
    return torch.special.ndtr(centred / sigma[:, :, None, None])


def _leave_one_out_product(factors: torch.Tensor, dim: int) -> torch.Tensor:
    """``prod_{o != i} factors[o]`` along ``dim`` for every ``i``, exact with zero factors."""
    is_zero = factors <= _TINY
    log_factors = torch.log(torch.where(is_zero, torch.ones_like(factors), factors))
    total_log = log_factors.sum(dim=dim, keepdim=True)
    zeros_elsewhere = is_zero.sum(dim=dim, keepdim=True) - is_zero.to(torch.int64)
    return torch.where(zeros_elsewhere > 0, torch.zeros_like(factors), torch.exp(total_log - log_factors))


def _value_and_gradient_chunk(logits, other_occupancy, n_directions, sigma_floor_voxels, with_gradient):
    """Works on the candidate voxels only: those with any support that no other object occupies.

    Every other voxel has ``h_s = 0`` for all ``s`` (factor 1 in ``u_s``, zero gradient) or is inside
    another object, where the object cannot be.
    """
    batch, size_x, size_y, size_z = logits.shape
    v = torch.sigmoid(logits.float())
    other = other_occupancy.float()
    directions = horizontal_directions(n_directions, device=logits.device)
    steps, step_of_direction = _direction_steps(directions)
    support_steps = _support_per_step(other, steps).flatten(2)
    beyond_columns = beyond_centre_of_mass_probability(v, directions, sigma_floor_voxels).flatten(2)

    candidate = (support_steps.amax(dim=1) > 0) & (other.flatten(1) < 0.5)
    n_candidates = int(candidate.sum(dim=1).max().clamp_min(1))
    order = torch.argsort(candidate.to(torch.int8), dim=1, descending=True, stable=True)
    index = order[:, :n_candidates]
    valid = torch.gather(candidate, 1, index).float()
    column = index // size_z

    v_c = torch.gather(v.flatten(1), 1, index)
    support = torch.gather(support_steps, 2, index.unsqueeze(1).expand(-1, len(steps), -1))
    support = support[:, step_of_direction] * valid.unsqueeze(1)
    beyond = torch.gather(beyond_columns, 2, column.unsqueeze(1).expand(-1, n_directions, -1))

    hold = (v_c.unsqueeze(1) * beyond * support).clamp(0.0, 1.0 - 1e-7)
    log_u = torch.log1p(-hold).sum(dim=2)
    one_minus_u = (-torch.expm1(log_u)).clamp_min(_TINY)
    log_probability = torch.log(one_minus_u).sum(dim=1)
    if not with_gradient:
        return log_probability, None
    support_hat = (support >= 0.5).float()
    exists = (v_c >= 0.5).float().unsqueeze(1)
    excluded_product = _leave_one_out_product(1.0 - beyond * exists * support_hat, dim=2)
    per_direction = beyond * support_hat * excluded_product / one_minus_u.unsqueeze(2)
    gradient = torch.zeros(batch, size_x * size_y * size_z, device=logits.device)
    gradient.scatter_add_(1, index, per_direction.sum(dim=1) * valid)
    return log_probability, gradient.view(batch, size_x, size_y, size_z)


def stability_value_and_gradient(
    logits: torch.Tensor,
    other_occupancy: torch.Tensor,
    n_directions: int = N_DIRECTIONS,
    sigma_floor_voxels: float = 0.25,
    with_gradient: bool = True,
    chunk_size: int = 16,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """``log P(E(v))`` ``[B]`` and the appendix-A ``d log P(E(v)) / d V`` ``[B, X, Y, Z]`` (unmasked).

    Batch items are processed ``chunk_size`` at a time to bound the ``[B, S, X, Y, Z]`` temporaries.
    """
    values, gradients = [], []
    with torch.no_grad():
        for start in range(0, logits.shape[0], chunk_size):
            chunk = slice(start, start + chunk_size)
            value, gradient = _value_and_gradient_chunk(
                logits[chunk], other_occupancy[chunk], n_directions, sigma_floor_voxels, with_gradient
            )
            values.append(value)
            gradients.append(gradient)
    gradient = torch.cat(gradients) if with_gradient else None
    return torch.cat(values), gradient


class StabilityLogProbability(torch.autograd.Function):
    """``log P(E(v))`` per batch item ``[B]`` from logits, with the appendix-A gradient."""

    @staticmethod
    def forward(ctx, logits, other_occupancy, unobserved_mask, n_directions, sigma_floor_voxels):
        with_gradient = ctx.needs_input_grad[0]
        log_probability, grad_v = stability_value_and_gradient(
            logits, other_occupancy, n_directions, sigma_floor_voxels, with_gradient
        )
        if with_gradient:
            v = torch.sigmoid(logits.float())
            grad_logits = grad_v * v * (1.0 - v) * unobserved_mask.float()
            ctx.save_for_backward(grad_logits)
        return log_probability.to(logits.dtype)

    @staticmethod
    def backward(ctx, grad_output):
        (grad_logits,) = ctx.saved_tensors
        scaled = grad_logits * grad_output.float().view(-1, 1, 1, 1)
        return scaled.to(grad_output.dtype), None, None, None, None


def stability_log_probability(
    logits: torch.Tensor,
    other_occupancy: torch.Tensor,
    unobserved_mask: torch.Tensor,
    n_directions: int = N_DIRECTIONS,
    sigma_floor_voxels: float = 0.25,
) -> torch.Tensor:
    """``log P(E(v))`` ``[B]``; its backward is the paper's approximate gradient (see module doc).

    ``logits``: ``[B, X, Y, Z]`` network output. ``other_occupancy``: the other objects' occupancy
    (probability or 0/1) in the same grid. ``unobserved_mask``: F4, the only voxels that get a gradient.
    """
    return StabilityLogProbability.apply(logits, other_occupancy, unobserved_mask, n_directions, sigma_floor_voxels)


def stability_loss(logits, other_occupancy, unobserved_mask, n_directions: int = N_DIRECTIONS) -> torch.Tensor:
    """Scalar loss ``-mean_b log P(E(v_b))``."""
    return -stability_log_probability(logits, other_occupancy, unobserved_mask, n_directions).mean()
